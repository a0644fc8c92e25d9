"""Calibrate ``agndc_core.plan.CALIBRATION``: the time of whole remesh runs per method.

For a few generated shapes (``shapes.generate_shape``: CAD parts and other families) at several
resolutions, times ``pipeline.remesh_mesh`` (voxelise, labels or network, contouring) per method
and the Chamfer distance of the output to its source (30k samples, what the Blender operator
reports), then fits seconds = a x crossed edges + b x lattice points + c per method by
non-negative least squares and prints the table in the form ``plan.py`` stores it, the current
table's predictions and each run's error.

Usage: python benchmarks/bench_estimate.py [--res 48 96 144] [--seeds 11 7 40]
       [--methods agndc undc mc sharp] [--threads 1]
"""

import argparse
import math
import time

import numpy as np
from scipy.optimize import nnls

from agndc_core import pipeline, plan
from agndc_core.metrics import evaluate
from agndc_core.pipeline import remesh_mesh
from agndc_core.study.shapes import generate_shape, shape_family

DISTANCE_SAMPLES = 30_000  # as agndc_blender/remesh.py


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--res", type=int, nargs="+", default=[48, 96, 144])
    parser.add_argument("--seeds", type=int, nargs="+", default=[11, 7, 40])
    parser.add_argument("--methods", nargs="+", default=["agndc", "undc", "mc", "sharp"])
    parser.add_argument("--threads", type=int, default=1)
    args = parser.parse_args()
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


if __name__ == "__main__":
    main()
