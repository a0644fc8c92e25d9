"""The one code path behind the operators, the batch script and scripting: Blender objects and
grid files in, new objects out, with ``agndc_core`` doing all the geometry.

Work is split in three steps so the interactive operators can run the middle one on a worker
thread (bpy is not thread-safe):

1. ``mesh_jobs`` / ``grid_jobs`` (main thread): check each input and copy it out of Blender into
   numpy, with its grid plan and time estimate. Nothing in the scene changes.
2. ``compute_jobs`` (any thread, numpy only): voxelise, reconstruct, measure distances.
   Every input succeeds or fails on its own (``Job.error``); cancelling stops them all.
3. ``apply_jobs`` (main thread): add the results of the inputs that succeeded, replacing the
   results of an earlier run of the same input and method, and return one ``Report`` per input.

Conventions: a mesh is remeshed as shown (modifiers applied) unless ``use_modifiers`` is off; it
is voxelised along its own axes with a voxel size in world units (the object's scale included);
results keep the source's transform, parent, materials (per face, from the nearest source face)
and sit beside it along its X axis where they overlap no other object (``plan.free_offset``), or
replace it (``replace_source``: the source is hidden, not deleted). A coloured grid (.vox) gives
one material per palette colour its faces use (``vox_rrggbb``, shared by name), each face
coloured by the nearest source voxel (``colors.face_colors``). ``remesh_object`` and
``import_grid`` chain the three steps for one input and raise its error.
"""

from __future__ import annotations

import threading
import traceback
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import bpy
import numpy as np
from mathutils import Matrix

from . import mesh_io
from ._core import checkpoint as checkpoint_module
from ._core import colors, errors, gridio, labelmaps, metrics, parallel, pipeline, plan, voxelize
from ._core import methods as registry
from ._core import options as options_module
from ._core import progress as progress_module

#: collection that receives the results placed beside their sources
COLLECTION_NAME = "AGNDC Results"
#: object-name suffix per method
#: fewer voxels than this along an object's longest side earn a warning (a blob, not a shape)
COARSE_VOXELS = 16
#: object-name suffix of each of the add-on's methods (the registry's labels)
SUFFIXES = {name: registry.BY_NAME[name].label for name in registry.BLENDER_METHODS}
#: surface samples per mesh for the Chamfer distance in the report (the paper's metric, fewer
#: samples than its 100k so the report costs a fraction of the remesh)
DISTANCE_SAMPLES = 30_000
#: what to do about a mesh that is not closed
OPEN_MESH_HINT = "add thickness (Solidify) or close the holes"
#: ``Settings.model_index`` for every model of a multi-model .vox file
ALL_MODELS = -1
#: custom properties that tie a result to its input, so a later run can replace it
TAG_SOURCE, TAG_FILE, TAG_MODEL, TAG_METHOD = ("agndc_source", "agndc_source_file",
                                               "agndc_model", "agndc_method")
#: custom property of a result made from one label of a label map (``Settings.per_label``)
TAG_LABEL = "agndc_label"
#: what a label map imported as one mask should do instead (``labelmaps.MergedLabelsWarning``)
MERGED_LABELS_HINT = "tick Per Label to import each label as its own object"
BUSY_MESSAGE = "Another AGNDC remesh is running: wait for it to finish or press Esc"

#: held while ``compute_jobs`` runs: a second run (operator, script, batch) cannot start beside it
_BUSY = threading.Lock()


@dataclass
class Settings:
    """What to do; the operators fill it from their properties, the batch script from argv."""

    resolution: int = 64  # voxels along the longest side, used when voxel_size is 0
    method: str = "agndc"
    normal_filter: bool = True  # learned methods: denoise the mesh, keeping creases (core remesh)
    decimate_error: float | None = None  # Low Poly: surface moved by at most this many voxels
    target_faces: int | None = None  # Low Poly: about this many faces (core decimate.py)
    threads: int = 0  # 0 = automatic
    compare_mc: bool = True
    smooth: bool = False
    quads: bool = False  # dual methods: planar, convex quads where the contouring made them
    checkpoint: str | None = None  # None = the shipped weights
    distance: bool = True  # Chamfer distance of each result to the source mesh
    voxel_size: float = 0.0  # voxel edge in world units; 0 = use ``resolution``
    use_modifiers: bool = True  # the evaluated mesh (modifiers applied); False: the base mesh
    replace_source: bool = False  # the result takes the source's place, the source is hidden
    model_index: int = 0  # .vox files: which model; ALL_MODELS = each model as an object
    colors: bool = True  # coloured grids (.vox): one material per used palette colour
    per_label: bool = False  # label maps (.nii .nii.gz .npy .npz): each label as an object
    labels: str = ""  # with per_label: only these labels ("1,3,7"); empty = every label

    def methods(self) -> list[str]:
        """The methods each input is reconstructed with (the result, then MC to compare)."""
        return run_methods(self.method, self.compare_mc, self.replace_source)

    def remesh_options(self, resolution: int | None = None):
        """The core's ``RemeshOptions`` of the chosen method (``resolution``: a mesh's)."""
        return options_module.RemeshOptions(
            method=self.method, resolution=resolution or self.resolution,
            checkpoint=self.checkpoint or None, threads=resolve_threads(self.threads),
            normal_filter=self.normal_filter, decimate_error=self.decimate_error,
            target_faces=self.target_faces)


def run_methods(method: str, compare_mc: bool, replace_source: bool) -> list[str]:
    """The chosen method, then marching cubes to compare unless it is MC or replaces the source
    (the operator's runs and the sidebar's estimate read this one rule)."""
    compare = compare_mc and method != "mc" and not replace_source
    return [method, "mc"] if compare else [method]


def estimate_run(methods, shape, crossings: float, threads: int, distances: bool) -> float:
    """Estimated seconds of one input's run (``plan.estimate_seconds`` per method) with the
    network's thread count (``resolve_threads``); with ``distances``, the Chamfer distance of
    each result to the source and one of the source to itself (its sampling noise)."""
    count = resolve_threads(threads) or parallel.default_threads()
    return sum(plan.estimate_seconds(method, shape, crossings, threads=count,
                                     distances=int(distances) * (2 if k == 0 else 1))
               for k, method in enumerate(methods))


@dataclass
class Output:
    """One reconstructed mesh, in the source's local (mesh) or the grid's world coordinates."""

    method: str
    vertices: np.ndarray  # (V, 3) float64
    faces: np.ndarray  # (F, 3) int64
    seconds: float
    cd: float | None = None  # Chamfer distance to the source (metrics.evaluate, raw)
    # the same measure of the source against itself (independent samples): differences below
    # twice this are sampling noise, not the method
    cd_noise: float | None = None
    materials: np.ndarray | None = None  # (F,) int32 material slot per face
    # coloured grids: (material name, (4,) linear RGBA) of each palette colour's slot, in order
    color_materials: list = field(default_factory=list)
    polygons: object = None  # quads.QuadMesh of the same faces (``Settings.quads``)


@dataclass
class Job:
    """One input (an object, or one model of a grid file) and, once computed, its outputs."""

    name: str
    source: str | None = None  # the source object's name (mesh input)
    vertices: np.ndarray | None = None  # (V, 3) float64 source mesh, local coords x frame
    faces: np.ndarray | None = None  # (F, 3) int64
    frame: np.ndarray = field(default_factory=lambda: np.ones(3))  # local -> voxelised frame
    face_materials: np.ndarray | None = None  # (F,) int32 slot per triangle (several slots)
    material_slots: list = field(default_factory=list)  # (material name or None, link)
    resolution: int = 0  # planned grid (mesh input)
    shape: tuple = ()
    grid_path: str | None = None
    grid: object = None  # the VoxelGrid read for the estimate (grid input), reused by the run
    model_index: int = 0
    label: int | None = None  # the label of a label map this job meshes (per-label import)
    matrix: np.ndarray = field(default_factory=lambda: np.eye(4))  # the source's matrix_world
    parent: str | None = None
    parent_inverse: np.ndarray = field(default_factory=lambda: np.eye(4))
    estimate: float = 0.0  # seconds (plan.estimate_seconds)
    crossings: float = 0.0  # crossed lattice edges of its grid (plan.mesh/grid_crossings)
    open_edges: int = 0
    warnings: list = field(default_factory=list)
    error: errors.AGNDCError | None = None
    outputs: list = field(default_factory=list)


@dataclass
class Made:
    """A new object and how it was made."""

    object: bpy.types.Object
    method: str
    faces: int
    seconds: float
    cd: float | None
    cd_noise: float | None = None


@dataclass
class Report:
    """What a run did with one input: the objects it added, or why it failed."""

    source: str
    made: list
    error: str | None = None
    warnings: list = field(default_factory=list)

    def summary(self) -> str:
        if self.error is not None:
            return f"{self.source}: {_without_name(self.error, self.source)}"
        parts = []
        for item in self.made:
            text = f"{SUFFIXES[item.method]} {item.faces:,} faces in {item.seconds:.2f} s"
            if item.cd is not None and item.cd_noise is not None \
                    and item.cd < 2 * item.cd_noise:
                text += f", CD within sampling noise (< {2 * item.cd_noise * 1e5:.2f}e-5)"
            elif item.cd is not None:
                text += f", CD {item.cd * 1e5:.2f}e-5"
            parts.append(text)
        return f"{self.source}: " + "; ".join(parts)


def summarize(reports: list[Report]) -> tuple[str, str]:
    """(report level, one line) for a whole run, e.g. ``('WARNING', '2 remeshed, 1 failed:
    Plane: open surface ... add thickness (Solidify) or close the holes')``."""
    failed = [r for r in reports if r.error is not None]
    done = len(reports) - len(failed)
    text = f"{done} remeshed"
    if failed:
        text += f", {len(failed)} failed: " + "; ".join(r.summary() for r in failed)
    # a failed input's warnings (e.g. "remeshed as the solid it encloses") did not come true
    warnings = [w for r in reports if r.error is None for w in r.warnings]
    if warnings:
        text += " | " + "; ".join(warnings)
    level = "ERROR" if not done else "WARNING" if failed or warnings else "INFO"
    return level, text


def _without_name(message: str, name: str) -> str:
    """A core message without its leading "name: " or "file name: " (the summary names the
    input itself: "pair: pair.vox: ..." says the file twice)."""
    head, sep, rest = message.partition(": ")
    token = head.strip("'")
    if sep and (token == name or ("." in token and name.startswith(token.split(".")[0]))):
        return rest
    return message


# --------------------------------------------------------------------------- step 1: prepare


def check_settings(settings: Settings) -> None:
    """Raise AGNDCError for settings no run can use."""
    if settings.method not in SUFFIXES:
        raise errors.AGNDCError(f"Unknown method {settings.method!r}; choose one of "
                                f"{', '.join(SUFFIXES)}")
    if settings.voxel_size < 0 or not np.isfinite(settings.voxel_size):
        raise errors.AGNDCError(f"Voxel size must be positive, got {settings.voxel_size}")
    if not settings.voxel_size and not (
            plan.RESOLUTION_MIN <= int(settings.resolution) <= plan.RESOLUTION_MAX):
        raise errors.AGNDCError(f"Resolution must be between {plan.RESOLUTION_MIN} and "
                                f"{plan.RESOLUTION_MAX}, got {settings.resolution}")
    if settings.threads < 0:
        raise errors.AGNDCError(f"Threads must be 0 (automatic) or more, got {settings.threads}")
    weights = checkpoint_path(settings.method, settings.checkpoint)
    if weights is not None and not weights.is_file():
        where = "custom checkpoint" if settings.checkpoint else "shipped weights"
        raise errors.ModelError(
            f"{SUFFIXES[settings.method]} needs its {where}, not found: {weights}. Choose "
            "Marching Cubes or Sharp, or set a checkpoint in the add-on preferences")


def frame_of(matrix: np.ndarray) -> tuple[np.ndarray, float]:
    """(frame (3,), world units per frame unit) of a world matrix.

    The mesh is voxelised in its local axes scaled by ``frame`` = the object's per-axis scale
    over its largest, so voxels are cubes in the world; axes whose scale equals the largest
    (within 1e-9, decomposition noise) get exactly 1, so a uniformly scaled object is voxelised
    in its own coordinates, bit for bit as ``remesh_mesh`` would.
    """
    scale = np.linalg.norm(np.asarray(matrix, dtype=np.float64)[:3, :3], axis=0)
    largest = float(scale.max())
    if not largest > 0:
        raise errors.MeshError("the object has zero scale")
    frame = np.where(np.isclose(scale, largest, rtol=1e-9, atol=0), 1.0, scale / largest)
    return frame, largest


def mesh_job(obj, settings: Settings, depsgraph=None) -> Job:
    """Check one object and copy its mesh out of Blender (main thread; changes nothing).

    Raises:
        AGNDCError naming the object and the problem.
    """
    if obj is None or obj.type != "MESH":
        kind = "nothing" if obj is None else f"'{obj.name}' is a {obj.type.lower()}"
        raise errors.MeshError(f"Select a mesh object to remesh ({kind})")
    name = obj.name
    vertices, faces, slots = mesh_io.read_mesh(obj, settings.use_modifiers, depsgraph)
    vertices, faces, used = voxelize.checked_surface(vertices, faces, source=f"'{name}'")
    matrix = np.array(obj.matrix_world, dtype=np.float64)
    frame, world_per_unit = frame_of(matrix)
    vertices, used = vertices * frame, used * frame
    extent = np.ptp(used, axis=0) * world_per_unit  # world units, along the object's axes
    grid = plan.plan_grid(extent, voxel_size=settings.voxel_size or None,
                          resolution=None if settings.voxel_size else settings.resolution,
                          source=f"'{name}'")
    job = Job(name=name, source=name, vertices=vertices, faces=faces, frame=frame,
              resolution=grid.resolution, shape=grid.shape, matrix=matrix,
              material_slots=[(s.material.name if s.material else None, s.link)
                              for s in obj.material_slots])
    if len(job.material_slots) > 1:
        job.face_materials = slots
    if obj.parent is not None:
        job.parent = obj.parent.name
        job.parent_inverse = np.array(obj.matrix_parent_inverse, dtype=np.float64)
    voxels = max(grid.shape) - 2 * plan.MARGIN
    if voxels < COARSE_VOXELS:
        job.warnings.append(f"{name} gets only {voxels} voxels along its longest side: its "
                            f"details are lost (a voxel size of at most "
                            f"{grid.voxel_size * voxels / COARSE_VOXELS:.3g} gives "
                            f"{COARSE_VOXELS}; or use Resolution)")
    job.open_edges = plan.open_edge_count(vertices, faces)
    if job.open_edges and plan.is_planar(used):
        raise _open_surface_error(name)
    if job.open_edges:
        job.warnings.append(f"{name} is not closed ({job.open_edges:,} open edges): remeshed as "
                            f"the solid it encloses; {OPEN_MESH_HINT}")
    job.crossings = plan.mesh_crossings(vertices * world_per_unit, faces, grid.voxel_size)
    job.estimate = estimate_run(settings.methods(), grid.shape, job.crossings, settings.threads,
                                settings.distance)
    return job


def _open_surface_error(name: str) -> errors.MeshError:
    """A mesh that is not closed and encloses nothing (a plane, one triangle)."""
    return errors.MeshError(f"'{name}': open surface with no inside to remesh: {OPEN_MESH_HINT}")


def mesh_jobs(objects, settings: Settings) -> list[Job]:
    """One job per mesh object among ``objects``; a bad object gets a job with its ``error``.

    Raises:
        AGNDCError for unusable settings or when there is no mesh at all.
    """
    check_settings(settings)
    meshes = [obj for obj in objects if obj is not None and obj.type == "MESH"]
    if not meshes:
        raise errors.MeshError("No mesh selected: select one or more mesh objects to remesh")
    if bpy.context.view_layer is not None:
        bpy.context.view_layer.update()  # current matrix_world after scripted transforms
    depsgraph = bpy.context.evaluated_depsgraph_get() if settings.use_modifiers else None
    jobs = []
    for obj in meshes:
        try:
            jobs.append(mesh_job(obj, settings, depsgraph))
        except errors.AGNDCError as exc:
            jobs.append(Job(name=obj.name, source=obj.name, error=exc))
    return jobs


def grid_jobs(paths, settings: Settings) -> list[Job]:
    """Jobs for grid files (main thread): one per file, or one per model of a .vox file with
    ``model_index=ALL_MODELS``; a file holding several models read one at a time gets a
    warning. Grids are read in ``compute_jobs``."""
    check_settings(settings)
    if settings.method in pipeline.MESH_ONLY_METHODS:
        raise errors.AGNDCError(f"{SUFFIXES[settings.method]} contours a mesh's own surface: "
                                "it needs a mesh, not a voxel grid; choose AGNDC, UNDC or MC")
    jobs = []
    for raw in paths:
        path = Path(bpy.path.abspath(str(raw))) if str(raw).startswith("//") else Path(raw)
        name = path.name[: -len(".nii.gz")] if path.name.lower().endswith(".nii.gz") \
            else path.stem
        try:
            jobs.extend(_grid_file_jobs(path, name, settings))
        except errors.AGNDCError as exc:
            jobs.append(Job(name=name, grid_path=str(path), error=exc))
    for job in jobs:
        if job.error is None:
            try:
                _estimate_grid_job(job, settings)
            except errors.AGNDCError as exc:
                job.error = exc
    return jobs


def _estimate_grid_job(job: Job, settings: Settings) -> None:
    """Read a grid job's grid (kept for the run; a label's is read with its label map) and
    estimate the run from its size and surface, as for meshes: a long import asks first
    (``operators.confirm_message``), the estimate of a per-label import covers every label."""
    if job.grid is None:
        job.grid = _read_grid(job)
    job.shape = tuple(job.grid.shape)
    job.crossings = plan.grid_crossings(job.grid.occupancy)
    # no source mesh: no Chamfer distance to report
    job.estimate = estimate_run(settings.methods(), job.shape, job.crossings, settings.threads,
                                distances=False)


def _read_grid(job: Job):
    """The grid of a grid job: one label of its label map, else the file's (model's) grid,
    with a warning when a label map is read as one mask (its labels merged)."""
    if job.label is not None:
        return labelmaps.load_label_map(job.grid_path).grid(job.label)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", labelmaps.MergedLabelsWarning)
        grid = gridio.load_grid(job.grid_path, model_index=job.model_index)
    job.warnings += [f"{w.message}; {MERGED_LABELS_HINT}" for w in caught
                     if issubclass(w.category, labelmaps.MergedLabelsWarning)]
    return grid


def _label_jobs(path: Path, name: str, settings: Settings) -> list[Job]:
    """One job per chosen label of a label map (``Settings.labels``), named
    ``<name>_label-<value>``, each holding its label's grid (cropped, in world place)."""
    volume = labelmaps.load_label_map(path)
    return [Job(name=labelmaps.label_name(name, label), grid_path=str(path), label=label,
                grid=volume.grid(label)) for label in volume.select(settings.labels)]


def _grid_file_jobs(path: Path, name: str, settings: Settings) -> list[Job]:
    if not gridio.is_grid_path(path):
        raise errors.GridFileError(f"{path.name}: not a grid file; expected one of "
                                   f"{', '.join(gridio.GRID_EXTENSIONS)}")
    if not path.is_file():
        raise errors.GridFileError(f"{path}: no such file")
    if settings.per_label:
        return _label_jobs(path, name, settings)
    count = gridio.grid_model_count(path)
    if settings.model_index == ALL_MODELS:
        if count == 1:
            return [Job(name=name, grid_path=str(path))]
        return [Job(name=f"{name}_model{k}", grid_path=str(path), model_index=k)
                for k in range(count)]
    if not 0 <= settings.model_index < count:
        raise errors.GridFileError(f"{path.name}: no model {settings.model_index}; the file "
                                   f"holds {count} (0..{count - 1})")
    job = Job(name=f"{name}_model{settings.model_index}" if count > 1 else name,
              grid_path=str(path), model_index=settings.model_index)
    if count > 1:
        job.warnings.append(f"{path.name} holds {count} models; imported model "
                            f"{settings.model_index} only (choose All Models to import each)")
    return [job]


def grid_job(path, settings: Settings) -> Job:
    """The job of one grid file (one model); raises its error."""
    (job, *_) = grid_jobs([path], settings)
    if job.error is not None:
        raise job.error
    return job


# --------------------------------------------------------------------------- step 2: compute


def resolve_threads(threads: int) -> int | None:
    """0 = automatic: every core in background runs, else all cores but one (for the UI)."""
    if threads > 0:
        return threads
    if bpy.app.background:
        return None
    return max(1, parallel.default_threads() - 1)


def compute_jobs(jobs: list[Job], settings: Settings, progress=None, cancel=None) -> None:
    """Fill ``job.outputs`` (or ``job.error``) of every job without one (no bpy access: safe on
    a worker thread). Only one call runs at a time.

    Args:
        progress: callable(fraction in [0, 1], message) or None; cancel: ``is_set()`` or None.

    Raises:
        CancelledError when cancelled (nothing is added to the scene then); AGNDCError when
        another run is in progress. Other failures are recorded per job.
    """
    if not _BUSY.acquire(blocking=False):
        raise errors.AGNDCError(BUSY_MESSAGE)
    try:
        todo = [job for job in jobs if job.error is None]
        weights = np.array([max(job.estimate, 0.05) if job.estimate else 1.0 for job in todo])
        starts = np.concatenate([[0.0], np.cumsum(weights)]) / max(weights.sum(), 1e-9)
        for job, lo, hi in zip(todo, starts[:-1], starts[1:]):
            def job_progress(fraction, message, lo=lo, hi=hi, job=job):
                if progress is not None:
                    progress(min(lo + (hi - lo) * fraction, 1.0), f"{job.name}: {message}")
            try:
                job.outputs = _compute(job, settings, job_progress, cancel)
            except errors.CancelledError:
                raise
            except errors.AGNDCError as exc:
                job.error = exc
            except MemoryError:
                job.error = errors.AGNDCError(
                    f"{job.name}: out of memory; use a larger voxel size (a smaller grid)")
            except Exception as exc:  # a bug: keep the traceback in the console, go on
                traceback.print_exception(exc)
                job.error = errors.AGNDCError(
                    f"{job.name}: internal error {exc!r} (see the system console)")
        if progress is not None:
            progress(1.0, "done")
    finally:
        _BUSY.release()


def is_busy() -> bool:
    """True while ``compute_jobs`` runs (on any thread)."""
    return _BUSY.locked()


def _compute(job: Job, settings: Settings, progress, cancel) -> list[Output]:
    methods = settings.methods()
    options = settings.remesh_options(job.resolution)
    stages = progress_module.Stages(progress, cancel, _expected_stages(job, settings, options))
    main_progress = _method_progress(stages, settings.method, settings.method)
    if job.grid_path is not None:
        stages.report(0.0, "reading grid")
        grid = job.grid if job.grid is not None else _read_grid(job)
        job.grid = None  # the run holds it now; the job does not keep it alive
        stages.check()
        first = pipeline.remesh(grid, options, progress=main_progress, cancel=cancel)
    else:
        try:
            first = pipeline.remesh_mesh(job.vertices, job.faces, options, source=f"'{job.name}'",
                                         progress=main_progress, cancel=cancel)
        except errors.GridError as exc:
            if not job.open_edges:
                raise
            raise _open_surface_error(job.name) from exc
    results = [first]
    for method in methods[1:]:  # marching cubes of the same grid, to compare
        stages.check()
        results.append(pipeline.remesh(first.grid, method=method, cancel=cancel,
                                       progress=_method_progress(stages, method,
                                                                 settings.method)))
    outputs = [Output(r.method, r.vertices, r.faces, r.seconds) for r in results]
    if settings.colors and results[0].grid is not None and results[0].grid.colors is not None:
        stages.report(stages.reported, "voxel colours")
        for output in outputs:
            _color_output(output, results[0].grid)
    noise = None
    if settings.distance and job.vertices is not None:
        noise = stages.run(NOISE_STAGE, metrics.chamfer_distance, job.vertices, job.faces,
                           job.vertices, job.faces, n_samples=DISTANCE_SAMPLES, seed=1,
                           check=stages.check)
    for output, result in zip(outputs, results):
        stages.check()
        if settings.distance and job.vertices is not None:
            output.cd = stages.run(_distance_stage(output.method), metrics.chamfer_distance,
                                   output.vertices, output.faces, job.vertices, job.faces,
                                   n_samples=DISTANCE_SAMPLES, check=stages.check)
            output.cd_noise = noise
        if job.face_materials is not None and len(output.faces):
            centroids = output.vertices[output.faces].mean(axis=1)  # (F, 3)
            output.materials = plan.nearest_face_values(job.vertices, job.faces,
                                                        job.face_materials, centroids)
        if settings.quads:  # a quad joins two triangles of one material only
            output.polygons = result.polygons(groups=output.materials)
        output.vertices = output.vertices / job.frame  # back to the object's local coordinates
    stages.report(1.0, "done")
    return outputs


#: the progress message of the Chamfer distance of the source to itself (its sampling noise)
NOISE_STAGE = "sampling noise of the distance"


def _distance_stage(method: str) -> str:
    return f"distance of {SUFFIXES[method]} to the source"


def _expected_stages(job: Job, settings: Settings, options) -> dict[str, float]:
    """{stage: expected seconds} of one job, in the order ``_compute`` runs them (the spans of
    its progress bar): each method's remesh (named by the method), then the distances."""
    points = pipeline.lattice_points(job.shape)
    size = {"crossings": job.crossings, "points": points}
    expected = {}
    for method in settings.methods():
        method_options = options_module.RemeshOptions.of(options, method=method)
        if job.vertices is not None and method == settings.method:
            stages = pipeline.expected_mesh_stages(method_options, triangles=len(job.faces),
                                                   **size)
        else:
            stages = pipeline.expected_stages(method_options, **size,
                                              bounded=job.vertices is not None)
        expected[method] = sum(stages.values())
    if settings.distance and job.vertices is not None:
        distance = plan.stage_seconds("distance", triangles=len(job.faces), **size)
        expected[NOISE_STAGE] = distance
        for method in settings.methods():
            expected[_distance_stage(method)] = distance
    return expected


def _method_progress(stages, method: str, chosen: str):
    """The progress callback of one method's remesh, over its span of the job's bar: the
    comparison's messages name their method ("MC marching cubes"; the status bar names the
    chosen one), and a remesh that ends says which ("Sharp done", not "done" mid-run)."""
    report = stages.sub(method)
    if report is None:
        return None
    label = SUFFIXES[method]
    prefix = "" if method == chosen else f"{label} "

    def forward(fraction, message):
        report(fraction, f"{label} done" if message == "done" else prefix + message)

    return forward


def _color_output(output: Output, grid) -> None:
    """One material slot per palette colour the faces use, each face in the slot of the nearest
    source voxel's colour (``colors.face_colors``; world = grid coordinates here)."""
    if not len(output.faces):
        return
    used, output.materials = colors.material_slots(
        colors.face_colors(output.vertices, output.faces, grid))
    palette = grid.colors.palette
    output.color_materials = [(colors.material_name(palette[index]),
                               tuple(colors.srgb_to_linear(palette[index]).tolist()))
                              for index in used]


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
    """Add the outputs of every computed job (main thread), select them, and report per job.

    Results of an earlier run of the same input and method are replaced (removed first, so the
    new ones take their place). Beside-source results are placed where they overlap no object.
    """
    scene = scene or bpy.context.scene
    done = [job for job in jobs if job.error is None and job.outputs]
    removed = set()
    for job in done:
        removed |= _remove_previous(job, [out.method for out in job.outputs])
    occupied = list(zip(*mesh_io.solid_bounds(scene, exclude=removed)))  # [(lo, hi)]
    reports = []
    for job in jobs:
        if job.error is not None or not job.outputs:
            error = job.error or errors.AGNDCError("not computed")
            reports.append(Report(job.name, [], str(error), job.warnings))
            continue
        made = [_add_output(job, k, out, settings, scene, occupied)
                for k, out in enumerate(job.outputs)]
        reports.append(Report(job.name, made, None, job.warnings))
    objects = [item.object for report in reports for item in report.made]
    if objects and bpy.context.view_layer is not None:
        for obj in bpy.context.selected_objects:
            obj.select_set(False)
        for obj in objects:
            if obj.name in bpy.context.view_layer.objects:
                obj.select_set(True)
        if objects[0].name in bpy.context.view_layer.objects:
            bpy.context.view_layer.objects.active = objects[0]
    return reports


def _remove_previous(job: Job, methods: list[str]) -> set[str]:
    """Remove the results an earlier run made from this job's input with these methods."""
    source = bpy.data.objects.get(job.source) if job.source else None
    old = [obj for obj in bpy.data.objects
           if obj.get(TAG_METHOD) in methods and (
               (source is not None and obj.get(TAG_SOURCE) == source) or
               (job.grid_path is not None and obj.get(TAG_FILE) == job.grid_path and
                obj.get(TAG_MODEL) == job.model_index and obj.get(TAG_LABEL) == job.label))]
    names = set()
    for obj in old:
        names.add(obj.name)
        mesh = obj.data
        bpy.data.objects.remove(obj)
        if mesh is not None and mesh.users == 0:
            bpy.data.meshes.remove(mesh)
    return names


def _add_output(job: Job, k: int, out: Output, settings: Settings, scene, occupied) -> Made:
    name = f"{job.name}_{SUFFIXES[out.method]}"
    mesh = mesh_io.new_mesh(name, out.vertices, out.faces, out.materials, out.polygons)
    mesh_io.set_smooth(mesh, settings.smooth)
    for material_name, link in job.material_slots:
        material = bpy.data.materials.get(material_name) if material_name else None
        mesh.materials.append(material if link == "DATA" else None)
    for material_name, rgba in out.color_materials:
        mesh.materials.append(mesh_io.color_material(material_name, rgba))
    obj = bpy.data.objects.new(name, mesh)
    for slot, (material_name, link) in zip(obj.material_slots, job.material_slots):
        if link == "OBJECT":
            slot.link = "OBJECT"
            slot.material = bpy.data.materials.get(material_name) if material_name else None
    source = bpy.data.objects.get(job.source) if job.source else None
    parent = bpy.data.objects.get(job.parent) if job.parent else None
    if parent is not None:
        obj.parent = parent
        obj.matrix_parent_inverse = Matrix(job.parent_inverse.tolist())
    replace = settings.replace_source and k == 0 and job.source is not None
    matrix = _placement(job, k, out, occupied, in_place=replace)
    obj.matrix_world = Matrix(matrix.tolist())
    collections = list(source.users_collection) if replace and source is not None else []
    for collection in collections or [results_collection(scene)]:
        collection.objects.link(obj)
    if source is not None:
        obj[TAG_SOURCE] = source
    if job.grid_path is not None:
        obj[TAG_FILE] = job.grid_path
        obj[TAG_MODEL] = job.model_index
        if job.label is not None:
            obj[TAG_LABEL] = job.label
    obj[TAG_METHOD] = out.method
    if replace and source is not None:
        source.hide_render = True
        if source.name in bpy.context.view_layer.objects:
            source.hide_set(True)
    return Made(obj, out.method, len(mesh.polygons), out.seconds, out.cd, out.cd_noise)


def _placement(job: Job, k: int, out: Output, occupied: list, in_place: bool) -> np.ndarray:
    """World matrix of output ``k``: the source's transform, moved along the source's X axis
    (grids: world X) by whole steps to the first place where its box overlaps no object's box
    in ``occupied`` (to which it is added). A replacing result stays at the source's place, the
    main result of a grid at the grid's world position (except .vox, which has none)."""
    lo, hi = mesh_io.box_bounds(_box_corners(out.vertices), job.matrix)
    grid = job.grid_path is not None
    if in_place or (k == 0 and grid and not job.grid_path.lower().endswith(".vox")):
        shift = np.zeros(3)
    else:
        boxes_lo = np.array([box[0] for box in occupied]).reshape(-1, 3)
        boxes_hi = np.array([box[1] for box in occupied]).reshape(-1, 3)
        direction = (1.0, 0.0, 0.0) if grid else job.matrix[:3, 0]
        shift = plan.free_offset(lo, hi, direction, boxes_lo, boxes_hi,
                                 start=0 if (k == 0 and grid) else 1)
    occupied.append((lo + shift, hi + shift))
    matrix = job.matrix.copy()
    matrix[:3, 3] += shift
    return matrix


def _box_corners(vertices: np.ndarray) -> np.ndarray:
    """(8, 3) corners of the axis-aligned box of (V, 3) vertices."""
    if len(vertices) == 0:
        return np.zeros((8, 3))
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    pick = np.array([[(c >> d) & 1 for d in range(3)] for c in range(8)], dtype=bool)
    return np.where(pick, hi, lo)


# --------------------------------------------------------------------------- one-call API


def remesh_object(obj, settings: Settings | None = None, progress=None, cancel=None) -> Report:
    """Remesh one mesh object; the source is never modified (``replace_source`` hides it).

    Returns:
        Report with the new objects (``<name>_AGNDC``, ``<name>_MC``...) and their statistics.

    Raises:
        AGNDCError with a user-ready message; the scene is then unchanged.
    """
    settings = settings or Settings()
    jobs = mesh_jobs([obj], settings)
    return _run_one(jobs, settings, progress, cancel)


def import_grid(path, settings: Settings | None = None, progress=None, cancel=None) -> Report:
    """Reconstruct a grid file (.npy .npz .binvox .vox .nii .nii.gz) into new objects placed in
    the grid's world coordinates (NIfTI keeps its world units; .vox models side by side)."""
    settings = settings or Settings()
    jobs = grid_jobs([path], settings)
    if len(jobs) > 1:
        raise errors.AGNDCError("import_grid reads one model or label; use grid_jobs for "
                                "several")
    return _run_one(jobs, settings, progress, cancel)


def _run_one(jobs, settings, progress, cancel) -> Report:
    if jobs[0].error is not None:
        raise jobs[0].error
    compute_jobs(jobs, settings, progress, cancel)
    if jobs[0].error is not None:
        raise jobs[0].error
    return apply_jobs(jobs, settings)[0]


def checkpoint_path(method: str, checkpoint: str | None = None) -> Path | None:
    """Weights file a learned method will load (None for marching cubes and sharp)."""
    if method not in pipeline.CHECKPOINT_NAMES:
        return None
    if checkpoint:
        return Path(bpy.path.abspath(checkpoint))
    return checkpoint_module.default_checkpoint_path(pipeline.CHECKPOINT_NAMES[method])
