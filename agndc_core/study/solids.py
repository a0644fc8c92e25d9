"""Geometric accuracy on analytic solids, in voxels: the quality targets for flat faces, sharp
corners and smooth curvature, measured the same way by ``benchmarks/bench_geometry.py`` and the
shipped-weights test.

Three solids are voxelised at ``resolution`` voxels on the longest side:

* an axis-aligned box: **flatness** = the largest distance of a face's vertices from that face's
  own best-fit plane, plus **box RMS**, their distance from the true plane;
* the box rotated 20 deg about x and 35 deg about y: **rotated RMS** = the RMS distance of face
  vertices from their true plane, and **corner** = the distance from each true corner to the
  nearest output vertex, worst of 8;
* a sphere: **sphere** = the RMS of the vertices' radial errors.

"Face vertices" are those closer than 0.75 voxel to one face plane and at least 1.5 voxels from
every other (edges and corners are judged by the corner error).
"""

from __future__ import annotations

import time

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from ..pipeline import remesh_mesh

#: the quality targets, in voxels (box RMS has none: a binary grid cannot place an axis-aligned
#: face within its layer, see labels.binary_oracle_vertex)
TARGETS = {"flatness": 0.05, "rotated_rms": 0.08, "corner": 0.5, "sphere": 0.08}
BOX_EXTENTS = (1.0, 0.7, 0.5)
SPHERE_RADIUS = 0.5
#: "face vertices": nearer than this to their face's plane, farther than EDGE_CLEARANCE from the
#: others (voxels)
FACE_BAND, EDGE_CLEARANCE = 0.75, 1.5


def rotated_box_transform() -> np.ndarray:
    """(4, 4) rotation of the rotated box: 20 deg about x after 35 deg about y."""
    about_x = trimesh.transformations.rotation_matrix(np.radians(20), [1, 0, 0])
    about_y = trimesh.transformations.rotation_matrix(np.radians(35), [0, 1, 0])
    return about_x @ about_y


def box_planes(extents, transform) -> tuple[np.ndarray, np.ndarray]:
    """(6, 3) outward normals and (6,) offsets of a centred box after ``transform``."""
    half = np.asarray(extents) / 2
    normals = np.concatenate([np.eye(3), -np.eye(3)])
    offsets = np.concatenate([half, half])
    return normals @ transform[:3, :3].T, offsets


def face_errors(vertices, normals, offsets, voxel: float) -> tuple[float, float]:
    """(flatness, rms) of the vertices that clearly belong to one face, in voxels."""
    distance = (vertices @ normals.T - offsets) / voxel  # (V, 6) signed, voxels
    order = np.argsort(np.abs(distance), axis=1)
    nearest, second = order[:, 0], order[:, 1]
    rows = np.arange(len(vertices))
    on_face = (np.abs(distance[rows, nearest]) < FACE_BAND) \
        & (np.abs(distance[rows, second]) > EDGE_CLEARANCE)
    flatness, squared = 0.0, []
    for face in range(6):  # six faces, each vectorised
        chosen = on_face & (nearest == face)
        if chosen.sum() < 3:
            continue
        squared.append(distance[chosen, face] ** 2)
        centred = vertices[chosen] - vertices[chosen].mean(0)
        fit_normal = np.linalg.svd(centred, full_matrices=False)[2][-1]
        flatness = max(flatness, float(np.abs(centred @ fit_normal).max() / voxel))
    if not squared:
        raise ValueError("no vertex lies clearly on a face of the box")
    return flatness, float(np.sqrt(np.concatenate(squared).mean()))


def corner_error(vertices, corners, voxel: float) -> float:
    """Worst distance from a true corner to its nearest output vertex, in voxels."""
    distance, _ = cKDTree(vertices).query(corners)
    return float(distance.max() / voxel)


def measure(method: str, resolution: int = 64, **options) -> dict:
    """Every error of the module docstring for one method, plus its wall seconds.

    ``options`` go to ``pipeline.remesh_mesh`` (checkpoint, threads, ...). The method sees
    the grid alone unless ``source_bounds=True`` is passed: the targets are about what is made
    of a grid, and the bounding box alone would put an axis-aligned box's faces exactly."""
    options.setdefault("source_bounds", False)
    straight = trimesh.creation.box(BOX_EXTENTS)
    turn = rotated_box_transform()
    rotated = trimesh.creation.box(BOX_EXTENTS, transform=turn)
    sphere = trimesh.creation.icosphere(6, SPHERE_RADIUS)
    start = time.perf_counter()
    results = [remesh_mesh(mesh.vertices, mesh.faces, resolution=resolution, method=method,
                           **options) for mesh in (straight, rotated, sphere)]
    seconds = time.perf_counter() - start
    box, rot, ball = results
    flatness, box_rms = face_errors(box.vertices, *box_planes(BOX_EXTENTS, np.eye(4)),
                                    box.grid.voxel_size[0])
    _, rotated_rms = face_errors(rot.vertices, *box_planes(BOX_EXTENTS, turn),
                                 rot.grid.voxel_size[0])
    radial = np.linalg.norm(ball.vertices, axis=1) - SPHERE_RADIUS
    return {"flatness": flatness, "box_rms": box_rms, "rotated_rms": rotated_rms,
            "corner": corner_error(rot.vertices, rotated.vertices, rot.grid.voxel_size[0]),
            "sphere": float(np.sqrt((radial**2).mean()) / ball.grid.voxel_size[0]),
            "seconds": seconds}
