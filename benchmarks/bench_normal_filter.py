"""Speed of the normal filter (agndc_core/normalfilter.py) on the shipped AGNDC's meshes.

    .venv/bin/python benchmarks/bench_normal_filter.py [--sizes 64 128] [--repeat 3]

For a generated CAD part voxelised at each size, the network's contoured mesh is filtered as
the pipeline filters it (``planar_v`` given, so the detail rule runs: here no vertex is marked
planar, the rule's most work); the baselines, measured in the same run on the same mesh, are
the dual contouring that made it, trimesh's Taubin smoothing (10 iterations, what
``mc_taubin`` runs) and the filter without the detail rule. A small mesh also times the
vectorised filter against ``filter_mesh_naive``, the loop-per-face reference.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np


def best_of(repeat: int, func, *args, **kwargs) -> tuple[float, object]:
    times, out = [], None
    for _ in range(repeat):
        start = time.perf_counter()
        out = func(*args, **kwargs)
        times.append(time.perf_counter() - start)
    return min(times), out


def main() -> None:
    import torch
    import trimesh

    from agndc_core.normalfilter import filter_mesh, filter_mesh_naive
    from agndc_core.pipeline import remesh_mesh, taubin_smooth
    from agndc_core.study.shapes import cad_part

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[64, 128])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    print(f"load average {os.getloadavg()[0]:.2f}")

    vertices, faces = cad_part(args.seed)
    for size in args.sizes:
        # the network's mesh as contoured; the filter is scale-free, so world units will do
        result = remesh_mesh(vertices, faces, resolution=size, method="agndc",
                             threads=args.threads, normal_filter=False, source_bounds=False)
        mesh_v, mesh_f = result.vertices, result.faces
        contour_s = result.timings["dual contouring"]
        none_planar = np.zeros(len(mesh_v), dtype=bool)
        filter_s, _ = best_of(args.repeat, filter_mesh, mesh_v, mesh_f, planar_v=none_planar)
        plain_s, _ = best_of(args.repeat, filter_mesh, mesh_v, mesh_f)
        taubin_s, _ = best_of(args.repeat, taubin_smooth, mesh_v, mesh_f)
        print(f"{size}³: {len(mesh_f):,} faces; normal filter {filter_s:.3f} s, dual contouring "
              f"{contour_s:.3f} s ({filter_s / contour_s:.2f}x), Taubin smoothing "
              f"{taubin_s:.3f} s ({filter_s / taubin_s:.2f}x), without the detail rule "
              f"{plain_s:.3f} s ({filter_s / plain_s:.2f}x)")

    sphere = trimesh.creation.icosphere(subdivisions=3)
    noisy = sphere.vertices + np.random.default_rng(0).normal(0, 0.01, sphere.vertices.shape)
    planar = np.random.default_rng(1).random(len(noisy)) < 0.1
    fast, out = best_of(args.repeat, filter_mesh, noisy, sphere.faces, planar_v=planar)
    slow, ref = best_of(1, filter_mesh_naive, noisy, sphere.faces, planar_v=planar)
    print(f"icosphere, {len(sphere.faces):,} faces: vectorised {fast * 1e3:.1f} ms, naive "
          f"{slow * 1e3:.0f} ms ({slow / fast:.0f}x); largest difference "
          f"{np.abs(out - ref).max():.1e}")


if __name__ == "__main__":
    main()
