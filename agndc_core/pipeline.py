"""The one ``remesh`` behind the CLI, the Blender operator, the batch script and the Python API.

    grid (VoxelGrid) --pad--> lattice --method--> (vertex offsets, edges) --dual_contour--> mesh

Methods:
    "agndc"  the AGNDC cascade with the shipped (or a given) checkpoint;
    "agndc_fast" the AGNDC cascade distilled for speed (no snake convolutions or attention,
             taught by agndc's own vertices; 1.5x as fast);
    "undc"   the single-scale plain-convolution baseline checkpoint (paper Table 4, first row);
    "surfacenets" surface nets (surfacenets.py): each dual vertex at the mean of its cell's
             crossed-edge midpoints, contoured like the networks' vertices; no weights;
    "mc"     marching cubes of the same grid (scikit-image);
    "mc_taubin" marching cubes followed by Taubin smoothing (trimesh, ``TAUBIN_ITERATIONS``
             steps, default lambda/nu), smoothed in lattice coordinates;
    "oracle" dual contouring of ground-truth labels: needs the source mesh (``remesh_mesh``);
             the ceiling any network can reach with this contouring.
    "oracle_binary" the oracle with what a binary grid cannot tell put back: on exactly
             axis-aligned faces the vertex sits at its layer's midpoint along the normal
             (``labels.binary_oracle_vertex``): an approximate ceiling for binary input.
    "sharp"  the same computation offered to users as a remesher for mesh input ("exact dual
             contouring"): each dual vertex minimises the quadratic error of the source mesh's
             own tangent planes inside its cell (a QEF, ``labels.py``), so flat faces stay flat
             and creases and corners stay where the source has them.

Topology: with binary input the crossed edges of the finest lattice are exactly the edges whose
end points differ, so the networks supply the vertex positions and the input supplies the edges
(and, through ``contour.dual_contour``, the split of ambiguous cells into patches); every output
is a closed 2-manifold. UNDC's alternative, the network's own edge head, is not offered: the
finest edge head is not trained (there is nothing to learn where the input gives the edges) and
it could only open holes or add sheets.

Orientation: faces are wound outward in world coordinates. An affine that mirrors space
(det < 0, common in NIfTI) turns index-space outward faces inward, so ``remesh`` reverses the
winding once, after the world mapping, for every method.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

import numpy as np

from .contour import dual_contour
from .errors import AGNDCError, MeshError
from .grid import LATTICE_PAD, VoxelGrid, crossed_edges, lattice_to_world, pad_to_lattice
from .methods import (  # noqa: F401  (the registry's lists, re-exported: one definition)
    BOUNDED_METHODS,
    BY_NAME,
    CHECKPOINT_NAMES,
    MESH_ONLY_METHODS,
    METHODS,
)
from .options import RemeshOptions
from .progress import (  # noqa: F401  (subrange: part of this module's API)
    Stages,
    raise_if_cancelled,
    subrange,
)

#: largest simplify tolerance (voxels) a target face count may use: beyond about a voxel the
#: count rises again, then falls only as voxel-sized features vanish (``decimate.py``)
TARGET_TOLERANCE = 1.0

#: fit the terraces of slightly tilted planes with one plane each (flatpatches.py)
TERRACED_PLANES = True
#: flatten the terraces a step runs round, recessed floors and plateaus (flatpatches.py)
STEPPED_FLOORS = True
#: Taubin smoothing passes of "mc_taubin" (trimesh alternates them: shrink by lambda, then
#: inflate by nu, so 10 is 5 of each)
TAUBIN_ITERATIONS = 10


@dataclass
class RemeshResult:
    """A reconstructed mesh in world coordinates.

    Attributes:
        vertices: (V, 3) float64 world coordinates; faces: (F, 3) int64, wound outward.
        method: the method that made it; seconds: wall time of ``remesh``;
        timings: seconds per stage; grid: the input grid.
        face_quads: (F,) int64 dual-contouring quad (crossed lattice edge) of each face, for
            the dual methods; None for marching cubes, which has no quads. ``polygons``
            joins the triangles back into quads.
    """

    vertices: np.ndarray
    faces: np.ndarray
    method: str
    seconds: float = 0.0
    timings: dict = field(default_factory=dict)
    grid: VoxelGrid | None = None
    face_quads: np.ndarray | None = None

    def polygons(self, **options):
        """The mesh as quads and triangles (``quads.quad_mesh``): the same surface, with each
        planar, convex pair of triangles of one dual-contouring quad joined into a quad."""
        from .quads import quad_mesh

        return quad_mesh(self, **options)


def planned_stages(options: RemeshOptions, *, bounded: bool = False) -> list[str]:
    """The stages ``remesh`` runs with ``options``, in order: the one list that the run itself
    and its progress bar's plan (``expected_stages``) both read.

    Args:
        bounded: the grid has source bounds (``VoxelGrid.source_bounds``: a voxelised mesh).
    """
    method = options.method
    if method in ("mc", "mc_taubin"):
        names = ["marching cubes"] + (["taubin smoothing"] if method == "mc_taubin" else [])
    else:
        learned = method in CHECKPOINT_NAMES
        names = ["surface nets" if method == "surfacenets" else
                 "predict" if learned else "intersection vertices"]
        if learned and options.flat_patches:
            names += ["flat patches"] + (["terraced planes"] if TERRACED_PLANES else [])
            names += ["stepped floors"] if STEPPED_FLOORS else []
        if options.source_bounds and method in BOUNDED_METHODS and bounded:
            names.append("source bounds")
        names.append("dual contouring")
        if learned:
            names += (["normal filter"] if options.normal_filter else []) + ["fold check"]
    if options.low_poly:
        names.append("low poly")
    return names


def expected_stages(options: RemeshOptions, *, crossings: float, points: float,
                    bounded: bool = False) -> dict[str, float]:
    """{stage: expected seconds} of ``remesh`` with ``options``, in the order it runs them
    (``planned_stages``, ``plan.stage_seconds``): the spans of its progress bar
    (``progress.Stages``).

    Args:
        crossings, points: the lattice's crossed edges and points; bounded: the grid has
            source bounds (``VoxelGrid.source_bounds``: a voxelised mesh).
    """
    from .plan import stage_seconds
    from .runtime.parallel import default_threads

    threads = options.threads or default_threads()  # what the network will run on
    return {name: stage_seconds(name, method=options.method, crossings=crossings,
                                points=points, threads=threads)
            for name in planned_stages(options, bounded=bounded)}


def remesh(grid: VoxelGrid, options: RemeshOptions | None = None, *, progress=None,
           cancel=None, labels=None, reframe: bool = True, **changes) -> RemeshResult:
    """Reconstruct a triangle mesh from a binary voxel grid.

    Args:
        grid: the input; a plain (X, Y, Z) array is accepted and placed at unit voxel size.
        options: the ``RemeshOptions`` of the run (method, network, filters, low poly; its
            docstring has each one); ``changes`` override its fields by name, e.g.
            ``remesh(grid, method="mc")``. The mesh-input fields (resolution, voxel_size,
            model_index) do not apply to a grid.
        progress: callable(fraction, message); cancel: object with ``is_set()``.
        labels: ground-truth ``ScaleLabels`` list, for MESH_ONLY_METHODS (use ``remesh_mesh``).
        reframe: let the network see the shape framed as a voxelised mesh is (empty margins as
            ``voxelize`` leaves them; ``inference.trained_window``), so a grid's own empty
            margins do not change the result. ``remesh_mesh`` turns it off: its grids are
            voxelised meshes, framed exactly as the training data were.

    The stages: the method's vertices (a network, surface nets, the labels' QEF vertices) or
    marching cubes; for a network's vertices the flat patches (``flatpatches.py``: each flat
    voxel-face patch that is not a terrace gets one depth); for dual methods on a voxelised
    mesh the source's bounding planes; dual contouring; for a network's mesh the normal filter
    (``normalfilter.py``: bilateral filtering of the face normals, creases kept) and the fold
    check; low poly when asked (``decimate.py``).
    """
    opts = RemeshOptions.of(options, **changes)
    method, checkpoint, threads, device = opts.method, opts.checkpoint, opts.threads, opts.device
    min_component_faces, tile = opts.min_component_faces, opts.tile
    decimate_error, target_faces = opts.decimate_error, opts.target_faces
    if not isinstance(grid, VoxelGrid):
        grid = VoxelGrid(grid)
    if method not in METHODS:
        raise AGNDCError(f"unknown method {method!r}; choose one of {', '.join(METHODS)}")
    grid.check_not_trivial()
    bounded = grid.source_bounds is not None
    planned = planned_stages(opts, bounded=bounded)  # the stages below run exactly these
    if "low poly" in planned:
        from .decimate import check_options

        check_options(decimate_error, target_faces)  # before the long stages, not after
    expected = None
    if progress is not None:  # the stages' spans of the bar, from the grid's size
        from .plan import grid_crossings

        expected = expected_stages(opts, crossings=grid_crossings(grid.occupancy),
                                   points=lattice_points(grid.shape),
                                   bounded=bounded)
    stages = Stages(progress, cancel, expected)
    face_quads = None
    if method in ("mc", "mc_taubin"):
        from .mc import marching_cubes_lattice

        lattice = pad_to_lattice(grid.occupancy, levels=0)
        vertices, faces = stages.run("marching cubes", marching_cubes_lattice, lattice)
        if "taubin smoothing" in planned:
            vertices = stages.run("taubin smoothing", taubin_smooth, vertices, faces)
    else:
        lattice = pad_to_lattice(grid.occupancy)
        if planned[0] == "surface nets":
            from .surfacenets import surface_nets_lattice

            vertex = stages.run("surface nets", surface_nets_lattice, lattice)
        else:
            # a network's vertices, or (mesh-only methods) those of the exact intersections
            name = planned[0]  # "predict" or "intersection vertices"
            vertex = stages.run(name, _predict, method, lattice, labels, checkpoint, threads,
                                device, tile, stages.sub(name), cancel, reframe)
        # where the flat-patch and bounds stages place a coordinate, the normal filter keeps it
        # (and the stepped floors leave the terraces a plane took)
        filtered = "normal filter" in planned  # a network's mesh
        pinned = (np.zeros(vertex.shape, dtype=bool)
                  if filtered or "stepped floors" in planned else None)
        if "flat patches" in planned:  # a network's vertices
            from .flatpatches import fit_terraced_planes, flatten_patches, flatten_stepped_floors

            vertex = stages.run("flat patches", flatten_patches, lattice, vertex,
                                in_place=True, pinned=pinned)
            if "terraced planes" in planned:
                vertex = stages.run("terraced planes", fit_terraced_planes, lattice, vertex,
                                    in_place=True, pinned=pinned)
            if "stepped floors" in planned:
                vertex = stages.run("stepped floors", flatten_stepped_floors, lattice, vertex,
                                    in_place=True, pinned=pinned)
        if "source bounds" in planned:
            vertex = stages.run("source bounds", _snap_to_source_bounds, grid, lattice, vertex,
                                pinned)
        edge = crossed_edges(lattice)
        # the later stages move vertices only: faces (and their quads) keep their order
        vertices, faces, face_quads = stages.run(
            "dual contouring", dual_contour, vertex, edge, lattice,
            min_component_faces=min_component_faces, face_quads=True)
        if filtered:
            vertices = stages.run("normal filter", filter_contoured_mesh, vertices, faces,
                                  vertex, pinned, check=stages.check)
        if "fold check" in planned:  # a network's vertices: no component turned inside out
            vertices = stages.run("fold check", unfold_components, vertices, faces, lattice,
                                  edge, min_component_faces, check=stages.check)
    if "low poly" in planned:
        from .decimate import decimate

        # lattice coordinates: one unit is one voxel along each axis
        vertices, faces = stages.run("low poly", decimate, vertices, faces,
                                     max_error=decimate_error, target_faces=target_faces,
                                     max_tolerance=TARGET_TOLERANCE)
        face_quads = None  # decimated faces belong to no dual-contouring quad: triangles only
    world = lattice_to_world(vertices, grid.affine)
    faces = orient_to_affine(faces, grid.affine)
    stages.report(1.0, "done")
    return RemeshResult(world, faces, method, stages.seconds, stages.timings, grid, face_quads)


def lattice_points(shape) -> int:
    """Points of a grid's padded lattice (``pad_to_lattice``, to within its rounding)."""
    return math.prod(int(n) + 2 * LATTICE_PAD for n in shape)


def unfold_components(vertices, faces, lattice, edge, min_component_faces: int = 0,
                      check=None):
    """Components the network turned inside out take their surface nets vertices
    (``contour.restore_folded_components``). The same lattice and edges give the same vertices
    in the same order (only the quads' diagonals follow the positions), so the surface nets
    vertices are compared on the network's own faces. ``check()`` runs between the two steps."""
    from .contour import restore_folded_components
    from .surfacenets import surface_nets_cells

    reference, reference_faces = dual_contour(lambda cells: surface_nets_cells(lattice, cells),
                                              edge, lattice,
                                              min_component_faces=min_component_faces)
    if check is not None:
        check()
    if reference.shape != vertices.shape or reference_faces.shape != faces.shape:
        return vertices  # not the same surfaces (cannot happen for one lattice): leave them
    return restore_folded_components(vertices, faces, reference)[0]


def filter_contoured_mesh(vertices, faces, vertex, pinned, check=None):
    """``normalfilter.filter_mesh`` of a contoured mesh, in lattice units (where the network's
    noise is the same along every axis), keeping the coordinates the flat-patch and bounds
    stages placed (``pinned``: (X, Y, Z, 3) bool over the cells' ``vertex`` offsets). The
    vertices they placed are on planar faces, where the filter's full vertex update runs even
    if the faces around bend like detail (``normalfilter.vertex_passes``)."""
    from .flatpatches import pinned_coordinates
    from .normalfilter import filter_mesh

    fixed = pinned_coordinates(vertices, vertex, pinned)  # (V, 3)
    return filter_mesh(vertices, faces, fixed_vx3=fixed, check=check,
                       planar_v=fixed.any(axis=1))


def _snap_to_source_bounds(grid: VoxelGrid, lattice: np.ndarray, vertex: np.ndarray,
                           pinned=None):
    """``flatpatches.snap_to_bounds`` with the grid's source bounds in lattice coordinates; a
    grid whose axes are not the world's (a rotated affine) has no axis-aligned bounding planes
    in its own frame and is left as it is."""
    from .flatpatches import snap_to_bounds

    linear = grid.affine[:3, :3]
    if np.count_nonzero(linear - np.diag(np.diag(linear))):
        return vertex
    corners = grid.world_to_index(grid.source_bounds) + LATTICE_PAD  # (2, 3)
    # a mirroring axis (negative voxel size) swaps which corner is the min one
    bounds = np.stack([corners.min(axis=0), corners.max(axis=0)])
    return snap_to_bounds(lattice, vertex, bounds, in_place=True, pinned=pinned)


def orient_to_affine(faces_fx3: np.ndarray, affine: np.ndarray) -> np.ndarray:
    """Faces wound outward in index space -> wound outward after ``affine``.

    A mirroring affine (det of its linear part < 0) reverses every triangle's orientation, so
    the winding is reversed to compensate; otherwise the faces are returned unchanged.

    Args:
        faces_fx3: (F, 3) int64 faces; affine: (4, 4) float64 index -> world map.
    """
    if np.linalg.det(np.asarray(affine, dtype=np.float64)[:3, :3]) < 0:
        return np.ascontiguousarray(faces_fx3[:, ::-1])
    return faces_fx3


def taubin_smooth(vertices_vx3: np.ndarray, faces_fx3: np.ndarray, *,
                  iterations: int = TAUBIN_ITERATIONS) -> np.ndarray:
    """Taubin (lambda|mu) smoothing of a mesh: (V, 3) float64 -> (V, 3) float64, same faces.

    trimesh's ``filter_taubin`` with its default lambda = nu = 0.5; it shrinks far less than
    plain Laplacian smoothing. Faces and vertex order are kept, so the topology is unchanged.
    """
    import trimesh
    from trimesh.smoothing import filter_taubin

    if len(faces_fx3) == 0:
        return vertices_vx3
    # process=False: keep marching cubes' vertex order (faces index it unchanged)
    mesh = trimesh.Trimesh(vertices_vx3.copy(), faces_fx3, process=False)
    filter_taubin(mesh, iterations=iterations)
    return np.asarray(mesh.vertices, dtype=np.float64)


def remesh_mesh(vertices, faces, options: RemeshOptions | None = None, *, source: str = "mesh",
                shift=(0.0, 0.0, 0.0), progress=None, cancel=None, **changes) -> RemeshResult:
    """Voxelise a mesh (in its own coordinates) at ``options.resolution`` and ``remesh`` the
    grid (``options`` and ``changes`` as for ``remesh``).

    ``shift`` moves the grid by a sub-voxel offset (``voxelize``; evaluation on shifted grids).

    For ``MESH_ONLY_METHODS`` ("oracle", "oracle_binary", "sharp") the ground-truth labels of
    the mesh (its exact intersections and normals) are contoured instead of a network's
    predictions.
    """
    from .voxelize import voxelize

    opts = RemeshOptions.of(options, **changes)
    # the expected times read every triangle of a dense mesh: Esc is honoured in between
    expected = (_expected_mesh_stages(vertices, faces, opts, lambda: raise_if_cancelled(cancel))
                if progress is not None else None)
    stages = Stages(progress, cancel, expected)
    grid = stages.run("voxelise", voxelize, vertices, faces, opts.resolution, shift=shift,
                      source=source, check=stages.check)
    labels = None
    if opts.method in MESH_ONLY_METHODS:
        from .labels import make_labels

        labels = stages.run("exact intersections", make_labels, vertices, faces, grid,
                            levels=0, check=stages.check)
    # a voxelised mesh is framed exactly as the training data were (voxelize + pad_to_lattice
    # leave its margins, thin unvoxelised ends included): re-framing it would only add noise
    result = remesh(grid, opts, progress=stages.sub("remesh"), cancel=cancel, labels=labels,
                    reframe=False)
    result.timings = {**stages.timings, **result.timings}
    # this function's clock started before voxelising and is still running: it already holds
    # the remesh (adding the two counted the remesh twice)
    result.seconds = stages.seconds
    return result


def _expected_mesh_stages(vertices, faces, options: RemeshOptions, check=None) -> dict | None:
    """{stage: expected seconds} of ``remesh_mesh``: voxelising and (mesh-only methods) the
    exact intersections grow with the triangles, the remesh of the grid with its size; None
    for a mesh ``voxelize`` will refuse (it says why). ``check()`` runs between chunks of the
    triangles (``plan.mesh_crossings``)."""
    from .plan import mesh_crossings
    from .voxelize import grid_layout

    vertices = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    extent = np.ptp(vertices, axis=0) if len(vertices) else np.zeros(3)
    if not (np.all(np.isfinite(extent)) and extent.max() > 0 and len(faces)
            and 3 <= options.resolution <= 1024):
        return None
    voxel, counts = grid_layout(extent, options.resolution)
    return expected_mesh_stages(options, triangles=len(faces), points=lattice_points(counts),
                                crossings=mesh_crossings(vertices, faces, voxel, check))


def expected_mesh_stages(options: RemeshOptions, *, triangles: int, crossings: float,
                         points: float) -> dict[str, float]:
    """{stage: expected seconds} of ``remesh_mesh`` from the mesh's and its grid's sizes:
    "voxelise", "exact intersections" (mesh-only methods) and "remesh" (``expected_stages``)."""
    from .plan import stage_seconds

    size = {"triangles": triangles, "crossings": crossings, "points": points}
    expected = {"voxelise": stage_seconds("voxelise", **size)}
    if options.method in MESH_ONLY_METHODS:
        expected["exact intersections"] = stage_seconds("exact intersections", **size)
    expected["remesh"] = sum(expected_stages(options, crossings=crossings, points=points,
                                             bounded=True).values())
    return expected


def remesh_file(path, options: RemeshOptions | None = None, *, progress=None, cancel=None,
                **changes) -> RemeshResult:
    """Read a grid or mesh file and remesh it: the one file path behind ``agndc remesh`` and
    ``agndc batch`` (``batch.remesh_many``); ``options`` and ``changes`` as for ``remesh``.

    A grid file (``gridio.GRID_EXTENSIONS``) is used as it is, in its own world units
    (``resolution`` and ``voxel_size`` do not apply; ``model_index`` picks a .vox model). A mesh
    is voxelised with ``resolution`` voxels along its longest side, or, when ``voxel_size`` is
    given, with voxels of at most that many world units (``resolution_for_voxel_size``).
    """
    from .gridio import is_grid_path, load_grid, load_mesh

    opts = RemeshOptions.of(options, **changes)
    path = Path(path)
    if is_grid_path(path):
        if opts.method in MESH_ONLY_METHODS:
            raise AGNDCError(f"{path.name}: --method {opts.method} needs a mesh as input (it "
                             "contours the mesh's own surface), not a voxel grid")
        return remesh(load_grid(path, model_index=opts.model_index), opts, progress=progress,
                      cancel=cancel)
    vertices, faces = load_mesh(path)
    if opts.voxel_size is not None:
        opts = RemeshOptions.of(opts, resolution=resolution_for_voxel_size(
            vertices, opts.voxel_size, source=path.name))
    return remesh_mesh(vertices, faces, opts, source=path.name, progress=progress,
                       cancel=cancel)


def resolution_for_voxel_size(vertices_vx3: np.ndarray, voxel_size: float, *,
                              source: str = "mesh") -> int:
    """The ``voxelize`` resolution whose voxels are at most ``voxel_size`` world units
    (``plan.plan_grid``, which also names the mesh and the limit when it is out of range)."""
    from .plan import plan_grid

    vertices = np.asarray(vertices_vx3, dtype=np.float64).reshape(-1, 3)
    extent = np.ptp(vertices, axis=0) if len(vertices) else np.zeros(3)
    return plan_grid(extent, voxel_size=voxel_size, source=source).resolution


def _predict(method, lattice, labels, checkpoint, threads, device, tile, progress, cancel,
             reframe=True):
    """(D, 3) vertex offsets of a learned method or a mesh-only method (the labels' vertices)."""
    if method in MESH_ONLY_METHODS:
        if labels is None:
            raise AGNDCError(f"method {method!r} contours the source mesh's own surface: it "
                             "needs a mesh as input (remesh_mesh), not a voxel grid alone")
        if labels[0].inside.shape != lattice.shape:
            raise MeshError("oracle labels do not match the grid's lattice")
        if method == "oracle_binary":
            from .labels import binary_oracle_vertex
            from .surfacenets import surface_nets_lattice

            return binary_oracle_vertex(labels[0], surface_nets_lattice(lattice))
        return labels[0].vertex
    from .inference import predict_lattice

    model = load_model(checkpoint or _default_checkpoint(method), device)
    set_inference_threads(threads, device)
    # the edges of a binary grid are its own: the network's vertices are all contouring needs
    vertex, _ = predict_lattice(model, lattice, device=None if device == "cpu" else device,
                                tile=tile, progress=progress, cancel=cancel, canonical=reframe,
                                edges=False, high_margin=BY_NAME[method].high_margin)
    return vertex


def set_inference_threads(threads: int | None, device: str = "cpu") -> int:
    """CPU threads of the network: ``threads``, or every core this process may use when None
    or 0 (so an "Auto" run after a ``threads=1`` run uses the cores again). Returns the count."""
    from .runtime.parallel import set_threads

    count = set_threads(threads)
    if device != "cpu" and "torch" in sys.modules:
        sys.modules["torch"].set_num_threads(count)
    return count


def _default_checkpoint(method: str) -> Path:
    from .checkpoint import default_checkpoint_path

    return default_checkpoint_path(CHECKPOINT_NAMES[method])


@lru_cache(maxsize=4)
def _load_torch_model(path: str, mtime: float):
    from .checkpoint import load_checkpoint

    model, _ = load_checkpoint(path)
    return model.eval()


def load_model(checkpoint, device: str = "cpu"):
    """The network of a checkpoint path, cached per process: the numpy runtime's ``Network``
    on the CPU (no torch), torch's ``AGNDCCascade`` on any other device."""
    path = Path(checkpoint)
    if device == "cpu":
        from .runtime import load_network

        return load_network(path)
    mtime = path.stat().st_mtime if path.exists() else 0.0
    return _load_torch_model(str(path), mtime)
