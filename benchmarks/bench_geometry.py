"""Geometric accuracy on analytic solids (issue 11's acceptance numbers), every method side by side.

    .venv/bin/python benchmarks/bench_geometry.py [--res 64] [--checkpoint agndc=PATH ...]

Three solids voxelised at ``--res`` voxels on the longest side, errors in voxels:

* axis-aligned box: **flatness** = largest distance of a face's vertices from that face's own
  best-fit plane (target <= 0.05 voxel), plus the distance from the true plane (RMS);
* box rotated 20 deg about x and 35 deg about y: **face RMS** distance of face vertices from their
  true plane (target <= 0.08), and **corner error** = distance from each true corner to the
  nearest output vertex, worst of 8 (target <= 0.5);
* sphere: **radial RMS** of the vertices (target <= 0.08).

"Face vertices" are those closer than 0.75 voxel to one face plane and at least 1.5 voxels
from every other (edges and corners are judged by the corner error). Marching cubes is the
ratio's baseline, measured in the same run.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import trimesh

from agndc_core.pipeline import remesh_mesh

METHODS = ("mc", "mc_taubin", "surfacenets", "undc", "agndc")


def box_planes(extents, transform):
    """(6, 3) outward normals and (6,) offsets of a centred box after ``transform``."""
    half = np.asarray(extents) / 2
    normals = np.concatenate([np.eye(3), -np.eye(3)])
    offsets = np.concatenate([half, half])
    rotation = transform[:3, :3]
    return normals @ rotation.T, offsets


def face_errors(vertices, normals, offsets, voxel):
    """(flatness, rms) of the vertices that clearly belong to one face, in voxels."""
    distance = (vertices @ normals.T - offsets) / voxel  # (V, 6) signed, voxels
    order = np.argsort(np.abs(distance), axis=1)
    nearest, second = order[:, 0], order[:, 1]
    rows = np.arange(len(vertices))
    on_face = (np.abs(distance[rows, nearest]) < 0.75) & (np.abs(distance[rows, second]) > 1.5)
    flatness, squared = 0.0, []
    for face in range(6):
        points = vertices[on_face & (nearest == face)]
        if len(points) < 3:
            continue
        squared.append(distance[on_face & (nearest == face), face] ** 2)
        centred = points - points.mean(0)
        fit_normal = np.linalg.svd(centred, full_matrices=False)[2][-1]
        flatness = max(flatness, float(np.abs(centred @ fit_normal).max() / voxel))
    return flatness, float(np.sqrt(np.concatenate(squared).mean()))


def corner_error(vertices, corners, voxel):
    from scipy.spatial import cKDTree

    distance, _ = cKDTree(vertices).query(corners)
    return float(distance.max() / voxel)


def run(method, mesh, res, checkpoints):
    start = time.perf_counter()
    result = remesh_mesh(mesh.vertices, mesh.faces, resolution=res, method=method,
                         checkpoint=checkpoints.get(method), threads=2)
    return result, result.grid.voxel_size[0], time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--res", type=int, default=64)
    parser.add_argument("--checkpoint", action="append", default=[], metavar="METHOD=PATH")
    args = parser.parse_args()
    checkpoints = dict(item.split("=", 1) for item in args.checkpoint)

    extents = (1.0, 0.7, 0.5)
    straight = trimesh.creation.box(extents)
    turn = trimesh.transformations.rotation_matrix(np.radians(20), [1, 0, 0]) @ \
        trimesh.transformations.rotation_matrix(np.radians(35), [0, 1, 0])
    rotated = trimesh.creation.box(extents, transform=turn)
    sphere = trimesh.creation.icosphere(6, 0.5)
    normals0, offsets0 = box_planes(extents, np.eye(4))
    normals1, offsets1 = box_planes(extents, turn)

    print(f"{args.res}³, errors in voxels; targets: flatness <= 0.05, rotated face RMS <= 0.08, "
          "corner <= 0.5, sphere radial RMS <= 0.08")
    print(f"{'method':12s} {'box flat':>9s} {'box RMS':>8s} {'rot RMS':>8s} {'corner':>7s} "
          f"{'sphere':>7s} {'s':>6s}")
    baseline = None
    for method in METHODS:
        try:
            box_result, voxel, t0 = run(method, straight, args.res, checkpoints)
            rot_result, voxel_r, t1 = run(method, rotated, args.res, checkpoints)
            sph_result, voxel_s, t2 = run(method, sphere, args.res, checkpoints)
        except Exception as exc:  # a missing checkpoint: report and go on
            print(f"{method:12s} failed: {exc}")
            continue
        flat, box_rms = face_errors(box_result.vertices, normals0, offsets0, voxel)
        _, rot_rms = face_errors(rot_result.vertices, normals1, offsets1, voxel_r)
        corners = rotated.vertices
        corner = corner_error(rot_result.vertices, corners, voxel_r)
        radial = np.linalg.norm(sph_result.vertices, axis=1) - 0.5
        sphere_rms = float(np.sqrt((radial**2).mean()) / voxel_s)
        seconds = t0 + t1 + t2
        baseline = seconds if baseline is None else baseline
        print(f"{method:12s} {flat:9.3f} {box_rms:8.3f} {rot_rms:8.3f} {corner:7.3f} "
              f"{sphere_rms:7.3f} {seconds:6.2f}  ({seconds / baseline:.0f}x mc time)")


if __name__ == "__main__":
    main()
