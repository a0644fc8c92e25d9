"""The one ``remesh`` behind the CLI, the Blender operator, the batch script and the Python API.

    grid (VoxelGrid) --pad--> lattice --method--> (vertex offsets, edges) --dual_contour--> mesh

Methods:
    "agndc"  the AGNDC cascade with the shipped (or a given) checkpoint;
    "undc"   the single-scale plain-convolution baseline checkpoint (paper Table 4, first row);
    "mc"     marching cubes of the same grid (scikit-image);
    "oracle" dual contouring of ground-truth labels: needs the source mesh (``remesh_mesh``);
             the ceiling any network can reach with this contouring.

Topology: with binary input the crossed edges of the finest lattice are exactly the edges whose
end points differ, so by default ("input") the networks supply the vertex positions and the input
supplies the edges; this keeps every output watertight. ``topology="predicted"`` uses the
network's own edge head (UNDC's behaviour), which may open holes or add sheets.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

import numpy as np

from .contour import dual_contour
from .errors import AGNDCError, CancelledError, MeshError
from .grid import LATTICE_PAD, VoxelGrid, pad_to_lattice
from .labels import crossed_edges

METHODS = ("agndc", "undc", "mc", "oracle")
TOPOLOGIES = ("input", "predicted")
#: default checkpoint name per learned method (agndc_core/weights/<name>.safetensors)
CHECKPOINT_NAMES = {"agndc": "agndc", "undc": "undc"}


@dataclass
class RemeshResult:
    """A reconstructed mesh in world coordinates.

    Attributes:
        vertices: (V, 3) float64 world coordinates; faces: (F, 3) int64, wound outward.
        method: the method that made it; seconds: wall time of ``remesh``;
        timings: seconds per stage; grid: the input grid.
    """

    vertices: np.ndarray
    faces: np.ndarray
    method: str
    seconds: float = 0.0
    timings: dict = field(default_factory=dict)
    grid: VoxelGrid | None = None


class _Stages:
    """Times named stages, reports progress and honours cancellation between them."""

    def __init__(self, progress, cancel):
        self.progress, self.cancel, self.timings = progress, cancel, {}
        self._start = time.perf_counter()

    def run(self, name: str, fraction: float, func, *args, **kwargs):
        if self.cancel is not None and self.cancel.is_set():
            raise CancelledError("remesh cancelled")
        if self.progress is not None:
            self.progress(fraction, name)
        start = time.perf_counter()
        out = func(*args, **kwargs)
        self.timings[name] = self.timings.get(name, 0.0) + time.perf_counter() - start
        return out

    @property
    def seconds(self) -> float:
        return time.perf_counter() - self._start


def remesh(grid: VoxelGrid, *, method: str = "agndc", checkpoint=None, threads: int | None = None,
           topology: str = "input", min_component_faces: int = 0, device: str = "cpu",
           tile: int | None = None, progress=None, cancel=None, labels=None) -> RemeshResult:
    """Reconstruct a triangle mesh from a binary voxel grid.

    Args:
        grid: the input; a plain (X, Y, Z) array is accepted and placed at unit voxel size.
        method: one of METHODS. "oracle" needs ``labels`` (use ``remesh_mesh``).
        checkpoint: path of a .safetensors checkpoint (learned methods); default: shipped weights.
        threads: torch CPU threads (default: torch's choice).
        topology: "input" or "predicted" (module docstring).
        min_component_faces: drop connected components smaller than this.
        tile: lattice tile size for large grids (learned methods); None = automatic.
        progress: callable(fraction, message); cancel: object with ``is_set()``.
        labels: ground-truth ``ScaleLabels`` list, for "oracle".
    """
    if not isinstance(grid, VoxelGrid):
        grid = VoxelGrid(grid)
    if method not in METHODS:
        raise AGNDCError(f"unknown method {method!r}; choose one of {', '.join(METHODS)}")
    if topology not in TOPOLOGIES:
        raise AGNDCError(f"unknown topology {topology!r}; choose one of {', '.join(TOPOLOGIES)}")
    grid.check_not_trivial()
    stages = _Stages(progress, cancel)
    if method == "mc":
        from .mc import marching_cubes_lattice

        lattice = pad_to_lattice(grid.occupancy, levels=0)
        vertices, faces = stages.run("marching cubes", 0.1, marching_cubes_lattice, lattice)
    else:
        lattice = pad_to_lattice(grid.occupancy)
        vertex, edge = stages.run("predict", 0.05, _predict, method, lattice, labels, checkpoint,
                                  threads, device, tile, progress, cancel)
        if topology == "input" or edge is None:
            edge = crossed_edges(lattice)
        vertices, faces = stages.run("dual contouring", 0.9, dual_contour, vertex, edge, lattice,
                                     min_component_faces=min_component_faces)
    world = grid.index_to_world(vertices - LATTICE_PAD)
    if progress is not None:
        progress(1.0, "done")
    return RemeshResult(world, faces, method, stages.seconds, stages.timings, grid)


def remesh_mesh(vertices, faces, *, resolution: int = 64, method: str = "agndc",
                source: str = "mesh", **options) -> RemeshResult:
    """Voxelise a mesh (in its own coordinates) at ``resolution`` and ``remesh`` the grid.

    For ``method="oracle"`` the ground-truth labels of the mesh are contoured instead of a
    network's predictions. Other keyword options are passed to ``remesh``.
    """
    from .voxelize import voxelize

    start = time.perf_counter()
    grid = voxelize(vertices, faces, resolution, source=source)
    voxel_seconds = time.perf_counter() - start
    if method == "oracle":
        from .labels import make_labels

        options["labels"] = make_labels(vertices, faces, grid, levels=0)
    result = remesh(grid, method=method, **options)
    result.timings = {"voxelise": voxel_seconds, **result.timings}
    result.seconds += voxel_seconds
    return result


def _predict(method, lattice, labels, checkpoint, threads, device, tile, progress, cancel):
    """(vertex (D, 3), edge (D, 3) bool or None) for a learned method or the oracle."""
    if method == "oracle":
        if labels is None:
            raise AGNDCError("the oracle contours ground-truth labels: call remesh_mesh with the "
                             "source mesh, not remesh with a grid alone")
        if labels[0].inside.shape != lattice.shape:
            raise MeshError("oracle labels do not match the grid's lattice")
        return labels[0].vertex, labels[0].edge
    import torch

    from .inference import predict_lattice

    if threads:
        torch.set_num_threads(int(threads))
    model = load_model(checkpoint or _default_checkpoint(method))
    vertex, edge_prob = predict_lattice(model, lattice, device=device, tile=tile,
                                        progress=progress, cancel=cancel)
    return vertex, edge_prob > 0.5


def _default_checkpoint(method: str) -> Path:
    from .checkpoint import default_checkpoint_path

    return default_checkpoint_path(CHECKPOINT_NAMES[method])


@lru_cache(maxsize=4)
def _load_model_cached(path: str, mtime: float):
    from .checkpoint import load_checkpoint

    model, _ = load_checkpoint(path)
    return model.eval()


def load_model(checkpoint):
    """Load (and cache per process) the network of a checkpoint path."""
    path = Path(checkpoint)
    mtime = path.stat().st_mtime if path.exists() else 0.0
    return _load_model_cached(str(path), mtime)
