"""Benchmark of the foundation's heavy steps, each against a baseline timed in the same run.

    voxelise  a ~100k-face CAD part at 128³   vs  trimesh's surface voxeliser + fill
    labels    all three scales at 64³          vs  marching cubes of the same 64³ grid
    contour   dual contouring of 128³ labels   vs  marching cubes of the same 128³ lattice

Usage: python benchmarks/bench_foundation.py [--repeat 3] [--seed 7]
"""

import argparse
import time

import trimesh

from agndc_core.contour import dual_contour
from agndc_core.grid import pad_to_lattice
from agndc_core.labels import make_labels
from agndc_core.mc import marching_cubes_lattice
from agndc_core.study.shapes import generate_shape
from agndc_core.voxelize import voxelize


def best_of(repeat, func, *args, **kwargs):
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        out = func(*args, **kwargs)
        times.append(time.perf_counter() - start)
    return min(times), out


def dense_part(seed: int, min_faces: int = 100_000):
    vertices, faces = generate_shape(seed)
    while len(faces) < min_faces:
        vertices, faces = trimesh.remesh.subdivide(vertices, faces)
    return vertices, faces


def trimesh_voxelise(mesh, pitch):
    return trimesh.voxel.creation.voxelize(mesh, pitch).fill().matrix


def row(name, ours, base, base_name):
    print(f"{name:<9} {ours * 1000:9.1f} ms   {base_name:<28} {base * 1000:9.1f} ms   "
          f"ratio {ours / base:5.2f}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--seed", type=int, default=7)
    args = parser.parse_args()

    vertices, faces = dense_part(args.seed)
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    print(f"CAD part seed {args.seed}: {len(faces):,} faces")
    t_vox, grid = best_of(args.repeat, voxelize, vertices, faces, 128)
    t_tm, _ = best_of(1, trimesh_voxelise, mesh, float(grid.voxel_size[0]))
    row("voxelise", t_vox, t_tm, "trimesh voxelize+fill 128³")

    small, small_faces = generate_shape(args.seed)
    grid64 = voxelize(small, small_faces, 64)
    t_lab, _ = best_of(args.repeat, make_labels, small, small_faces, grid64)
    lattice64 = pad_to_lattice(grid64.occupancy)
    t_mc64, _ = best_of(args.repeat, marching_cubes_lattice, lattice64)
    row("labels", t_lab, t_mc64, "marching cubes 64³")

    grid128 = voxelize(small, small_faces, 128)
    labels = make_labels(small, small_faces, grid128, levels=0)[0]
    t_dc, (v, f) = best_of(args.repeat, dual_contour, labels.vertex, labels.edge, labels.inside)
    t_mc, _ = best_of(args.repeat, marching_cubes_lattice, labels.inside)
    row("contour", t_dc, t_mc, "marching cubes 128³")
    print(f"(contour output: {len(v):,} vertices, {len(f):,} faces; best of {args.repeat})")


if __name__ == "__main__":
    main()
