"""What a user describes: the scene dataclasses, their errors and the TOML scene files."""

from .bodies import Pair, Part, bodies_scene
from .description import (
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
from .load_history import History
from .toml import load_scene, scene_from_dict

__all__ = [
    "Body",
    "Box",
    "Contact",
    "Coulomb",
    "Dirichlet",
    "History",
    "Material",
    "MeshFile",
    "NormalCompliance",
    "Obstacle",
    "Pair",
    "Part",
    "Rectangle",
    "Scene",
    "SceneError",
    "Signorini",
    "Traction",
    "Tresca",
    "bodies_scene",
    "load_scene",
    "scene_from_dict",
]
