"""What a user describes: the scene dataclasses, their errors and the TOML scene files."""

from .model import (
    Body,
    Contact,
    Dirichlet,
    Material,
    MeshFile,
    Obstacle,
    Rectangle,
    Scene,
    SceneError,
    Signorini,
    Traction,
)
from .toml import load_scene, scene_from_dict

__all__ = [
    "Body",
    "Contact",
    "Dirichlet",
    "Material",
    "MeshFile",
    "Obstacle",
    "Rectangle",
    "Scene",
    "SceneError",
    "Signorini",
    "Traction",
    "load_scene",
    "scene_from_dict",
]
