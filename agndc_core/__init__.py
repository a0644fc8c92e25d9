"""AGNDC Remesher core: binary voxel grids to triangle meshes (bpy-free).

Public API (re-exports only)."""

from .errors import AGNDCError, GridError, GridFileError, MeshError, ModelError
from .grid import VoxelGrid

__all__ = [
    "AGNDCError",
    "GridError",
    "GridFileError",
    "MeshError",
    "ModelError",
    "VoxelGrid",
]
