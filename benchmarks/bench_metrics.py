"""Cost of the full metric set (agndc_core.metrics.evaluate) on one CAD-like mesh pair.

The ground truth is a procedural CAD shape; the "prediction" is the same shape subdivided
and jittered (a reconstruction-like mesh with many small faces). Baseline from the same run:
only the two k-d tree builds and queries of a plain Chamfer distance on the same 100k-point
samples, so the ratio shows what sampling, NC, F1 and the edge metrics add. Target: evaluate
<= 3 s per pair on a 2-core CPU.

    .venv/bin/python benchmarks/bench_metrics.py [--seed 3] [--repeat 3]
"""

import argparse
import time

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from agndc_core import metrics as M
from agndc_core.study.shapes import generate_shape

TARGET_S = 3.0
JITTER = 0.0005  # vertex noise of the fake prediction, normalised units (1/30 of a 64^3 cell)
MAX_EDGE = 0.02  # subdivide the prediction to ~this edge length: ~10^4-10^5 faces


def _pair(seed: int):
    """(gt_vertices, gt_faces, pred_vertices, pred_faces) for one benchmark case."""
    gt_v, gt_f = generate_shape(seed)
    pred_v, pred_f = trimesh.remesh.subdivide_to_size(gt_v, gt_f, MAX_EDGE)
    pred_v = pred_v + np.random.default_rng(seed).normal(0, JITTER, pred_v.shape)
    return gt_v, gt_f, pred_v, pred_f


def _best_of(repeat: int, fn) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def _plain_cd(a: np.ndarray, b: np.ndarray) -> float:
    """Chamfer distance of two point sets: two tree builds and two queries, nothing else."""
    d_ab = cKDTree(b).query(a)[0]
    d_ba = cKDTree(a).query(b)[0]
    return float(np.mean(d_ab**2) + np.mean(d_ba**2))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=3, help="shape seed of the mesh pair")
    ap.add_argument("--repeat", type=int, default=3, help="timed runs; the best is reported")
    args = ap.parse_args()
    gt_v, gt_f, pred_v, pred_f = _pair(args.seed)
    row = M.evaluate(pred_v, pred_f, gt_v, gt_f)
    t_eval = _best_of(args.repeat, lambda: M.evaluate(pred_v, pred_f, gt_v, gt_f))
    gt_pts, _ = M.sample_surface(gt_v, gt_f, M.N_SAMPLES, 0)
    pred_pts, _ = M.sample_surface(pred_v, pred_f, M.N_SAMPLES, 1)
    t_cd = _best_of(args.repeat, lambda: _plain_cd(gt_pts, pred_pts))
    print(f"pair: GT {len(gt_f)} faces, prediction {len(pred_f)} faces, "
          f"{M.N_SAMPLES} samples each")
    print("metrics (paper units): "
          + ", ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}"
                    for k, v in M.format_row(row).items()))
    print(f"evaluate: {t_eval:.3f} s, plain CD: {t_cd:.3f} s, ratio {t_eval / t_cd:.1f} "
          f"(target evaluate <= {TARGET_S:.0f} s: {'OK' if t_eval <= TARGET_S else 'MISSED'})")


if __name__ == "__main__":
    main()
