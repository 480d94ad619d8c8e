"""convexcontact: frictional contact of linear elastic bodies as exact convex programs.

Build a :class:`Scene`, call :func:`solve`, read the :class:`ContactResult`::

    import convexcontact as cc
    result = cc.solve(cc.library.hertz_punch(), solver="clarabel")
    print(result.max_pressure, result.certificate.worst)
    result.save("out")
"""

from .conic import ConicProgram, ConicSolution
from .drivers.adapt import adapt
from .drivers.history_run import HistoryResult
from .drivers.history_run import run as run_history
from .drivers.parameters import with_parameter
from .drivers.prepared import Model, prepare
from .drivers.sensitivity import gradient, sensitivity
from .drivers.solutions import SolutionSet, all_solutions
from .drivers.solve import solve
from .results.result import ContactResult
from .scene import bodies_library, library
from .scene.bodies import Pair, Part, bodies_scene
from .scene.description import (
    Body,
    Box,
    Contact,
    Coulomb,
    Dirichlet,
    Material,
    MeshFile,
    NormalCompliance,
    Obstacle,
    Rectangle,
    Scene,
    SceneError,
    Signorini,
    Traction,
    Tresca,
)
from .scene.load_history import History
from .scene.toml import load_scene

__all__ = [
    "Body", "Box", "ConicProgram", "ConicSolution", "Contact", "ContactResult", "Coulomb", "Dirichlet", "History",
    "HistoryResult", "Material", "MeshFile", "Model", "NormalCompliance", "Obstacle", "Pair", "Part", "Rectangle",
    "Scene", "SceneError", "Signorini", "SolutionSet", "Traction", "Tresca", "adapt", "all_solutions", "bodies_library",
    "bodies_scene", "gradient", "library", "load_scene", "prepare", "run_history", "sensitivity", "solve",
    "with_parameter",
]
__version__ = "0.1.0"
