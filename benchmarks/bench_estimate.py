"""Calibrate ``agndc_core.plan.CALIBRATION``: the time of whole remesh runs per method.

For a few generated shapes (``shapes.generate_shape``: CAD parts and other families) at several
resolutions, times ``pipeline.remesh_mesh`` (voxelise, labels or network, contouring) per method
and the Chamfer distance of the output to its source (30k samples, what the Blender operator
reports), then fits seconds = a x crossed edges + b x lattice points + c per method by
non-negative least squares and prints the table in the form ``plan.py`` stores it, the current
table's predictions and each run's error.

With ``--stages`` it calibrates ``plan.STAGE_SECONDS`` and ``plan.NETWORK_SECONDS`` instead, the
expected seconds of each stage that spread the progress bar (``agndc_core/progress.py``): the
stage times (``RemeshResult.timings``) of a generated CAD part subdivided to ``--triangles``
triangles (the voxeliser, Sharp's intersections and the distance grow with them) at each
``--res``, and of the brain-sized grid of ``bench_inference.py``, fitted per stage as seconds =
a x million triangles + b x million crossed edges + c x million lattice points (no constant:
the stages' fixed costs are milliseconds, and a fitted constant would soak up the other terms'
shortfall and predict seconds for the smallest inputs). ``--samples FILE`` also writes every
(stage, triangles, crossings, points, seconds) as JSON.

Usage: python benchmarks/bench_estimate.py [--res 48 96 144] [--seeds 11 7 40]
       [--methods agndc undc mc sharp] [--threads 1]
       python benchmarks/bench_estimate.py --stages [--res 64 128]
       [--triangles 12288 196608 786432 3145728] [--threads 2]
"""

import argparse
import math
import time

import numpy as np
from scipy.optimize import nnls

from agndc_core import pipeline, plan
from agndc_core.metrics import chamfer_distance, evaluate
from agndc_core.pipeline import remesh_mesh
from agndc_core.study.shapes import generate_shape, shape_family

DISTANCE_SAMPLES = 30_000  # as agndc_blender/remesh.py


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--res", type=int, nargs="+", default=None,
                        help="default: 48 96 144 (--stages: 64 128)")
    parser.add_argument("--seeds", type=int, nargs="+", default=[11, 7, 40])
    parser.add_argument("--methods", nargs="+", default=None,
                        help="default: agndc undc mc sharp (--stages: every method)")
    parser.add_argument("--threads", type=int, default=None,
                        help=f"default: 1 (--stages: {plan.FIT_THREADS})")
    parser.add_argument("--stages", action="store_true",
                        help="fit the per-stage table of the progress bar instead")
    parser.add_argument("--triangles", type=int, nargs="+",
                        default=[12288, 196608, 786432, 3145728])
    parser.add_argument("--samples", help="--stages: write the stage times to this JSON file")
    args = parser.parse_args()
    if args.stages:
        return fit_stages(args)
    args.res = args.res or [48, 96, 144]
    args.methods = args.methods or ["agndc", "undc", "mc", "sharp"]
    args.threads = args.threads or 1
    pipeline.set_inference_threads(args.threads)
    rows = {m: [] for m in [*args.methods, "distance"]}
    for seed in args.seeds:
        vertices, faces = generate_shape(seed)
        remesh_mesh(vertices, faces, resolution=16, method="agndc")  # warm-up: load, import
        for res in args.res:
            grid_plan = plan.plan_grid(np.ptp(vertices, axis=0), resolution=res)
            crossings = plan.mesh_crossings(vertices, faces, grid_plan.voxel_size)
            points = math.prod(n + 2 for n in grid_plan.shape)
            for method in args.methods:
                start = time.perf_counter()
                result = remesh_mesh(vertices, faces, resolution=res, method=method,
                                     threads=args.threads)
                seconds = time.perf_counter() - start
                rows[method].append((crossings, points, seconds))
                start = time.perf_counter()
                evaluate(result.vertices, result.faces, vertices, faces,
                         n_samples=DISTANCE_SAMPLES)
                rows["distance"].append((crossings, 0, time.perf_counter() - start))
                print(f"seed {seed} ({shape_family(seed)}) {res}³ {method}: {seconds:.2f} s, "
                      f"{crossings / 1e6:.3f} M crossings, {points / 1e6:.2f} M points, "
                      f"estimate {plan.estimate_seconds(method, grid_plan.shape, crossings):.2f}",
                      flush=True)
    print("\nCALIBRATION = {")
    for method, data in rows.items():
        data = np.array(data)
        design = np.column_stack([data[:, 0] / 1e6, data[:, 1] / 1e6, np.ones(len(data))])
        coef, _ = nnls(design, data[:, 2])
        error = design @ coef / data[:, 2] - 1
        print(f'    "{method}": ({coef[0]:.3g}, {coef[1]:.3g}, {coef[2]:.3g}),  '
              f"# {len(data)} runs, error {error.min():+.0%}..{error.max():+.0%}")
    print("}")


#: the methods of a stage fit: every stage a remesh can run, low poly on the first
STAGE_METHODS = ("agndc", "agndc_fast", "undc", "sharp", "mc", "mc_taubin", "surfacenets")
#: the stages that read the source mesh, whose time grows with its triangles
MESH_STAGES = ("voxelise", "exact intersections", "distance")


def fit_stages(args):
    """Time every stage of every method on dense CAD parts and the brain-sized grid, then fit
    and print ``STAGE_SECONDS`` and ``NETWORK_SECONDS`` (see the module docstring)."""
    import os
    import sys

    import trimesh

    from agndc_core.pipeline import remesh
    from agndc_core.study.shapes import cad_part

    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    from bench_inference import make_grid

    threads = args.threads or plan.FIT_THREADS
    methods = args.methods or STAGE_METHODS
    pipeline.set_inference_threads(threads)
    samples: dict[str, list] = {}  # stage -> [(triangles, crossings, points, seconds)]

    def add(result, triangles, label=None):
        crossings = plan.grid_crossings(result.grid.occupancy) / 1e6
        points = math.prod(n + 2 for n in result.grid.shape) / 1e6
        for stage, seconds in result.timings.items():
            key = f"network {result.method}" if stage == "predict" else stage
            samples.setdefault(key, []).append((triangles / 1e6, crossings, points, seconds))
        return crossings, points

    vertices, faces = cad_part(7)
    remesh_mesh(vertices, faces, resolution=16, method="agndc")  # warm-up: load, import
    meshes = {}
    while len(faces) <= max(args.triangles):
        meshes[len(faces)] = (vertices, faces)
        vertices, faces = trimesh.remesh.subdivide(vertices, faces)
    for count in args.triangles:
        vertices, faces = meshes[count]
        for res in args.res or [64, 128]:
            for method in methods:
                changes = {"decimate_error": 0.25} if method == methods[0] else {}
                result = remesh_mesh(vertices, faces, resolution=res, method=method,
                                     threads=threads, **changes)
                crossings, points = add(result, count)
                for seed in (0, 1):  # the output against the source, the source against itself
                    output = (result.vertices, result.faces) if seed == 0 else (vertices, faces)
                    start = time.perf_counter()
                    chamfer_distance(*output, vertices, faces, n_samples=DISTANCE_SAMPLES,
                                     seed=seed)
                    samples.setdefault("distance", []).append(
                        (count / 1e6, crossings, 0.0, time.perf_counter() - start))
                print(f"{count:,} triangles {res}³ {method}: {result.seconds:.2f} s "
                      f"({', '.join(f'{k} {v:.2f}' for k, v in result.timings.items())})",
                      flush=True)
    grid = make_grid("brain")
    for method in methods:
        if method in pipeline.MESH_ONLY_METHODS:
            continue
        result = remesh(grid, method=method, threads=threads)
        add(result, 0)
        print(f"brain {method}: {result.seconds:.2f} s", flush=True)
    if args.samples:
        import json

        with open(args.samples, "w", encoding="utf-8") as handle:
            json.dump(samples, handle)
    print(f"\n# {threads} threads, load average {os.getloadavg()[0]:.1f}")
    for name, keys in (("STAGE_SECONDS", [k for k in samples if not k.startswith("network")]),
                       ("NETWORK_SECONDS", [k for k in samples if k.startswith("network")])):
        print(f"{name} = {{")
        for key in keys:
            data = np.array(samples[key])
            design = data[:, :3].copy()
            if key not in MESH_STAGES:  # a grid's stages do not see the source's triangles
                design[:, 0] = 0.0
            coef, _ = nnls(design, data[:, 3])
            error = np.abs(design @ coef - data[:, 3]).max()
            label = key.removeprefix("network ")
            print(f'    "{label}": ({", ".join(f"{c:.3g}" for c in coef)}),  '
                  f"# {len(data)} runs, at most {error:.2f} s off, longest "
                  f"{data[:, 3].max():.2f} s")
        print("}")


if __name__ == "__main__":
    main()
