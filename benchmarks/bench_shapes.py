"""Throughput of the procedural shape generator (agndc_core.study.shapes).

Generates ``--n`` shapes and prints shapes/s and the extrapolated time for 1,000 shapes
(target: under 5 minutes). Baseline from the same run: building and meshing the same number
of plain unit boxes with ``Manifold.cube``, so the ratio shows the cost of the booleans.

    .venv/bin/python benchmarks/bench_shapes.py --n 200
"""

import argparse
import time

import numpy as np
from manifold3d import Manifold

from agndc_core.study.shapes import generate_shape

TARGET_1000_S = 300.0  # 1,000 training shapes in under 5 minutes


def _time_shapes(n: int, seed0: int) -> tuple[float, int]:
    """Seconds to generate ``n`` shapes, and their total face count."""
    t0 = time.perf_counter()
    n_faces = sum(len(generate_shape(seed)[1]) for seed in range(seed0, seed0 + n))
    return time.perf_counter() - t0, n_faces


def _time_boxes(n: int) -> float:
    """Seconds to build and mesh ``n`` unit boxes (same output conversion as the generator)."""
    t0 = time.perf_counter()
    for _ in range(n):
        mesh = Manifold.cube((1.0, 1.0, 1.0), center=True).to_mesh64()
        np.asarray(mesh.vert_properties, dtype=np.float64), np.asarray(mesh.tri_verts)
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=200, help="number of shapes")
    ap.add_argument("--seed0", type=int, default=0, help="first seed")
    args = ap.parse_args()
    t_shapes, n_faces = _time_shapes(args.n, args.seed0)
    t_boxes = _time_boxes(args.n)
    per_1000 = t_shapes / args.n * 1000
    print(f"shapes: {args.n} in {t_shapes:.2f} s = {args.n / t_shapes:.1f} shapes/s "
          f"(mean {n_faces / args.n:.0f} faces)")
    print(f"extrapolated 1000 shapes: {per_1000:.1f} s (target < {TARGET_1000_S:.0f} s: "
          f"{'OK' if per_1000 < TARGET_1000_S else 'MISSED'})")
    print(f"plain boxes: {t_boxes:.3f} s, ratio shapes/boxes {t_shapes / t_boxes:.0f}x")


if __name__ == "__main__":
    main()
