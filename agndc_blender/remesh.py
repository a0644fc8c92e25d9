"""The one code path behind the operators, the batch script and scripting: Blender objects and
grid files in, new objects out, with ``agndc_core`` doing all the geometry.

Work is split in three steps so the interactive operators can run the middle one on a worker
thread (bpy is not thread-safe):

1. ``mesh_job`` / ``grid_job`` (main thread): validate everything and copy the input out of
   Blender into numpy. Nothing in the scene changes.
2. ``compute_jobs`` (any thread, numpy/torch only): voxelise, reconstruct, measure distances.
   A failure or cancellation here still leaves the scene untouched.
3. ``apply_jobs`` (main thread): add the new objects, in one go, to the results collection.

``remesh_object`` and ``import_grid`` chain the three steps synchronously.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import bpy
import numpy as np
from mathutils import Matrix

from . import mesh_io
from ._core import errors, gridio, metrics, pipeline
from .properties import RESOLUTION_MAX, RESOLUTION_MIN

#: collection that receives every new object
COLLECTION_NAME = "AGNDC Results"
#: object-name suffix per method
SUFFIXES = {"agndc": "AGNDC", "undc": "UNDC", "mc": "MC"}
#: surface samples per mesh for the Chamfer distance in the report (the paper's metric, fewer
#: samples than its 100k so the report costs a fraction of the remesh)
DISTANCE_SAMPLES = 30_000
#: gap between side-by-side results, as a fraction of the source's width
SIDE_GAP = 0.25


@dataclass
class Settings:
    """What to do; the operators fill it from their properties, the batch script from argv."""

    resolution: int = 64
    method: str = "agndc"
    threads: int = 0  # 0 = automatic
    compare_mc: bool = True
    smooth: bool = False
    checkpoint: str | None = None  # None = the shipped weights
    distance: bool = True  # Chamfer distance of each result to the source mesh


@dataclass
class Output:
    """One reconstructed mesh, in the source's local (mesh) or the grid's world coordinates."""

    method: str
    vertices: np.ndarray  # (V, 3) float64
    faces: np.ndarray  # (F, 3) int64
    seconds: float
    cd: float | None = None  # Chamfer distance to the source (metrics.evaluate, raw)


@dataclass
class Job:
    """One input (an object or a grid file) and, once computed, its outputs."""

    name: str
    vertices: np.ndarray | None = None  # (V, 3) float64 source mesh, local coordinates
    faces: np.ndarray | None = None  # (F, 3) int64
    grid_path: str | None = None
    matrix: np.ndarray = field(default_factory=lambda: np.eye(4))  # placement of the outputs
    step: float = 0.0  # world-space X offset between neighbouring objects (0: from the output)
    materials: list = field(default_factory=list)  # material names of the source
    outputs: list = field(default_factory=list)


@dataclass
class Made:
    """A new object and how it was made."""

    object: bpy.types.Object
    method: str
    faces: int
    seconds: float
    cd: float | None


@dataclass
class Report:
    """What ``remesh_object`` / ``import_grid`` added for one input."""

    source: str
    made: list

    def summary(self) -> str:
        parts = []
        for item in self.made:
            text = f"{SUFFIXES[item.method]} {item.faces:,} faces in {item.seconds:.2f} s"
            if item.cd is not None:
                text += f", CD {item.cd * 1e5:.2f}e-5"
            parts.append(text)
        return f"{self.source}: " + "; ".join(parts)


# --------------------------------------------------------------------------- step 1: validate


def check_settings(settings: Settings) -> None:
    """Raise AGNDCError for settings no run can use."""
    if not RESOLUTION_MIN <= int(settings.resolution) <= RESOLUTION_MAX:
        raise errors.AGNDCError(f"Resolution must be between {RESOLUTION_MIN} and "
                                f"{RESOLUTION_MAX}, got {settings.resolution}")
    if settings.method not in SUFFIXES:
        raise errors.AGNDCError(f"Unknown model {settings.method!r}; choose one of "
                                f"{', '.join(SUFFIXES)}")
    if settings.threads < 0:
        raise errors.AGNDCError(f"Threads must be 0 (automatic) or more, got {settings.threads}")
    weights = checkpoint_path(settings.method, settings.checkpoint)
    if weights is not None and not weights.is_file():
        where = "custom checkpoint" if settings.checkpoint else "shipped weights"
        raise errors.ModelError(
            f"{SUFFIXES[settings.method]} needs its {where}, not found: {weights}. Choose "
            "Marching Cubes, or set a checkpoint in the add-on preferences")


def mesh_job(obj, settings: Settings) -> Job:
    """Validate one object and copy its mesh out of Blender (main thread; changes nothing)."""
    check_settings(settings)
    if obj is None or obj.type != "MESH":
        kind = "nothing" if obj is None else f"'{obj.name}' is a {obj.type.lower()}"
        raise errors.MeshError(f"Select a mesh object to remesh ({kind})")
    vertices, faces = mesh_io.read_mesh(obj)
    if len(faces) == 0:
        raise errors.MeshError(f"'{obj.name}' has no faces: only closed surfaces can be remeshed")
    if not np.all(np.isfinite(vertices)) or np.ptp(vertices, axis=0).max() <= 0:
        raise errors.MeshError(f"'{obj.name}' has zero size or invalid coordinates")
    lo, hi = mesh_io.world_bounds(obj)
    width = float(hi[0] - lo[0]) or float((hi - lo).max())
    return Job(name=obj.name, vertices=vertices, faces=faces,
               matrix=np.array(obj.matrix_world, dtype=np.float64),
               step=width * (1.0 + SIDE_GAP),
               materials=[m.name if m is not None else None for m in obj.data.materials])


def mesh_jobs(objects, settings: Settings) -> list[Job]:
    """Jobs for the mesh objects among ``objects``; AGNDCError if there is none or one is bad."""
    check_settings(settings)
    meshes = [obj for obj in objects if obj is not None and obj.type == "MESH"]
    if not meshes:
        raise errors.MeshError("No mesh selected: select one or more mesh objects to remesh")
    if bpy.context.view_layer is not None:
        bpy.context.view_layer.update()  # current matrix_world after scripted transforms
    return [mesh_job(obj, settings) for obj in meshes]


def grid_job(path, settings: Settings) -> Job:
    """Validate a grid file's name and presence (main thread); it is read in ``compute_jobs``."""
    check_settings(settings)
    path = Path(bpy.path.abspath(str(path))) if str(path).startswith("//") else Path(path)
    if not gridio.is_grid_path(path):
        raise errors.GridFileError(f"{path.name}: not a grid file; expected one of "
                                   f"{', '.join(gridio.GRID_EXTENSIONS)}")
    if not path.is_file():
        raise errors.GridFileError(f"{path}: no such file")
    stem = path.name[: -len(".nii.gz")] if path.name.lower().endswith(".nii.gz") else path.stem
    return Job(name=stem, grid_path=str(path))


# --------------------------------------------------------------------------- step 2: compute


def resolve_threads(threads: int) -> int | None:
    """0 = automatic: torch's default in background runs, else all cores but one (for the UI)."""
    if threads > 0:
        return threads
    if bpy.app.background:
        return None
    return max(1, (os.cpu_count() or 2) - 1)


def compute_jobs(jobs: list[Job], settings: Settings, progress=None, cancel=None) -> None:
    """Fill ``job.outputs`` for every job (no bpy access: safe on a worker thread).

    Args:
        progress: callable(fraction in [0, 1], message) or None; cancel: ``is_set()`` or None.

    Raises:
        AGNDCError (CancelledError when cancelled); outputs of earlier jobs are kept but nothing
        is added to the scene.
    """
    for index, job in enumerate(jobs):
        def job_progress(fraction, message, index=index, job=job):
            if progress is not None:
                progress((index + fraction) / len(jobs), f"{job.name}: {message}")
        job.outputs = _compute(job, settings, job_progress, cancel)


def _compute(job: Job, settings: Settings, progress, cancel) -> list[Output]:
    def check_cancel():
        if cancel is not None and cancel.is_set():
            raise errors.CancelledError("Remesh cancelled")

    options = dict(checkpoint=settings.checkpoint or None,
                   threads=resolve_threads(settings.threads), cancel=cancel)
    main_share = 0.75 if settings.compare_mc and settings.method != "mc" else 0.9

    def sub(lo, hi):
        return lambda f, msg: progress(lo + (hi - lo) * f, msg)

    if job.grid_path is not None:
        progress(0.0, "reading grid")
        grid = gridio.load_grid(job.grid_path)
        check_cancel()
        first = pipeline.remesh(grid, method=settings.method, progress=sub(0.0, main_share),
                                **options)
    else:
        first = pipeline.remesh_mesh(job.vertices, job.faces, resolution=int(settings.resolution),
                                     method=settings.method, source=job.name,
                                     progress=sub(0.0, main_share), **options)
    results = [first]
    if settings.compare_mc and settings.method != "mc":
        check_cancel()
        results.append(pipeline.remesh(first.grid, method="mc", cancel=cancel,
                                       progress=sub(main_share, 0.9)))
    outputs = [Output(r.method, r.vertices, r.faces, r.seconds) for r in results]
    if settings.distance and job.vertices is not None:
        for output in outputs:
            check_cancel()
            progress(0.9, f"distance of {SUFFIXES[output.method]} to the source")
            output.cd = float(metrics.evaluate(output.vertices, output.faces, job.vertices,
                                               job.faces, n_samples=DISTANCE_SAMPLES)["cd"])
    progress(1.0, "done")
    return outputs


# --------------------------------------------------------------------------- step 3: apply


def results_collection(scene) -> bpy.types.Collection:
    """The results collection, created and linked to ``scene`` when needed."""
    collection = bpy.data.collections.get(COLLECTION_NAME)
    if collection is None:
        collection = bpy.data.collections.new(COLLECTION_NAME)
    if collection.name not in {c.name for c in scene.collection.children_recursive}:
        scene.collection.children.link(collection)
    return collection


def apply_jobs(jobs: list[Job], settings: Settings, scene=None) -> list[Report]:
    """Add one object per output of every computed job (main thread) and select them."""
    scene = scene or bpy.context.scene
    collection = results_collection(scene)
    reports = [Report(job.name, [_add_output(job, k, out, settings, collection)
                                 for k, out in enumerate(job.outputs)]) for job in jobs]
    made = [item.object for report in reports for item in report.made]
    if made and bpy.context.view_layer is not None:
        for obj in bpy.context.selected_objects:
            obj.select_set(False)
        for obj in made:
            obj.select_set(True)
        bpy.context.view_layer.objects.active = made[0]
    return reports


def _add_output(job: Job, k: int, out: Output, settings: Settings, collection) -> Made:
    name = f"{job.name}_{SUFFIXES[out.method]}"
    mesh = mesh_io.new_mesh(name, out.vertices, out.faces)
    mesh_io.set_smooth(mesh, settings.smooth)
    for material_name in job.materials:
        mesh.materials.append(bpy.data.materials.get(material_name) if material_name else None)
    obj = bpy.data.objects.new(name, mesh)
    step = job.step
    if step <= 0 and len(out.vertices):  # grid: side by side at the first output's width
        first = job.outputs[0].vertices
        step = float(np.ptp(first[:, 0])) * (1.0 + SIDE_GAP) if len(first) else 0.0
    # the source's placement, shifted along world X: first result one step to the source's
    # right (mesh) or in place (grid), the next one a step further
    offset = (k + (1 if job.vertices is not None else 0)) * step
    matrix = job.matrix.copy()
    matrix[0, 3] += offset
    obj.matrix_world = Matrix(matrix.tolist())
    collection.objects.link(obj)
    return Made(obj, out.method, len(mesh.polygons), out.seconds, out.cd)


# --------------------------------------------------------------------------- one-call API


def remesh_object(obj, settings: Settings | None = None, progress=None, cancel=None) -> Report:
    """Remesh one mesh object; the source is never modified.

    Returns:
        Report with the new objects (``<name>_AGNDC``, ``<name>_MC``...) and their statistics.

    Raises:
        AGNDCError with a user-ready message; the scene is then unchanged.
    """
    settings = settings or Settings()
    jobs = mesh_jobs([obj], settings)
    compute_jobs(jobs, settings, progress, cancel)
    return apply_jobs(jobs, settings)[0]


def import_grid(path, settings: Settings | None = None, progress=None, cancel=None) -> Report:
    """Reconstruct a grid file (.npy .npz .binvox .vox .nii .nii.gz) into new objects placed in
    the grid's world coordinates (NIfTI keeps its world units)."""
    settings = settings or Settings()
    jobs = [grid_job(path, settings)]
    compute_jobs(jobs, settings, progress, cancel)
    return apply_jobs(jobs, settings)[0]


def checkpoint_path(method: str, checkpoint: str | None = None) -> Path | None:
    """Weights file a learned method will load (None for marching cubes).

    Mirrors ``agndc_core.checkpoint.default_checkpoint_path`` without importing torch, so the
    sidebar can show the status cheaply.
    """
    if method not in pipeline.CHECKPOINT_NAMES:
        return None
    if checkpoint:
        return Path(bpy.path.abspath(checkpoint))
    name = pipeline.CHECKPOINT_NAMES[method]
    return Path(pipeline.__file__).resolve().parent / "weights" / f"{name}.safetensors"
