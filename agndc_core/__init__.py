"""AGNDC Remesher core: binary voxel grids to triangle meshes (bpy-free).

The public API, re-exported here (resolved on first use, so ``import agndc_core`` stays light)::

    from agndc_core import RemeshOptions, load_grid, remesh, save_mesh
    result = remesh(load_grid("chair.binvox"), method="agndc")
    save_mesh(result.vertices, result.faces, "chair.obj")
    options = RemeshOptions(method="agndc", target_faces=5000)  # every option, in one place
    result = remesh(load_grid("chair.binvox"), options)
"""

from importlib import import_module

from .errors import AGNDCError, CancelledError, GridError, GridFileError, MeshError, ModelError
from .grid import VoxelGrid

__version__ = "0.1.0"

#: public name -> the module that defines it
_LAZY = {
    "remesh": "pipeline", "remesh_mesh": "pipeline", "remesh_file": "pipeline",
    "RemeshResult": "pipeline", "METHODS": "pipeline", "RemeshOptions": "options",
    "remesh_labels": "labelmaps", "load_label_map": "labelmaps",
    "load_grid": "gridio", "load_mesh": "gridio", "save_mesh": "gridio",
    "voxelize": "voxelize",
    "evaluate": "metrics",
}

__all__ = [
    "AGNDCError", "CancelledError", "GridError", "GridFileError", "MeshError", "ModelError",
    "VoxelGrid", "__version__", *_LAZY,
]


def __getattr__(name):
    if name in _LAZY:
        return getattr(import_module(f".{_LAZY[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
