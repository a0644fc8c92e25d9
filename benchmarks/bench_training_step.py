"""Benchmark of one AGNDC training step (finest scale, dense crops), against the gather snake.

The training path evaluates the dynamic snake convolutions densely (``DenseOps.snake``, one
fused ``grid_sample`` over all taps). The baseline measured in the same run is the previous
implementation: 4 bilinear corners per tap from ``common.snake_corners``, clamped to the lattice
and gathered (what ``BandOps`` still does on the sparse band at inference). Both are timed on the
same batch, alternating, after a warm-up step; the snake outputs are checked to agree first.

Usage: python benchmarks/bench_training_step.py --data FOLDER [--width 16] [--batch 4]
       [--crop 32] [--threads 2] [--repeat 3]
FOLDER holds training samples (``agndc train-data``); a handful is enough.
"""

import argparse
import statistics
import tempfile
import time

import torch

from agndc_core.nn import dense_ops
from agndc_core.nn.common import snake_corners
from agndc_core.training.train import TrainConfig, Trainer


def gather_snake(self, y, offsets, axis, radius=None):
    """The baseline: (B, X, Y, Z, K b) projected taps -> (B, X, Y, Z, b) by a 4-corner gather."""
    bsz, nx, ny, nz, kb = y.shape
    k = offsets.shape[-1]
    n = nx * ny * nz
    axes = [torch.arange(m, device=y.device) for m in self.shape]
    coords = torch.stack(torch.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3).repeat(bsz, 1)
    corners, weights = snake_corners(coords, offsets.reshape(bsz * n, 2, k), axis)
    hi = torch.tensor(self.shape, device=y.device) - 1
    corners = torch.minimum(corners.clamp_min(0), hi)
    batch = torch.arange(bsz, device=y.device).repeat_interleave(n)[:, None, None]
    rows = batch * n + (corners[..., 0] * ny + corners[..., 1]) * nz + corners[..., 2]
    taps = torch.arange(k, device=y.device)[None, :, None]
    values = y.reshape(bsz * n * k, kb // k)[rows * k + taps]  # (B N, K, 4, b)
    return (values * weights[..., None]).sum((1, 2)).reshape(bsz, nx, ny, nz, kb // k)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", required=True)
    parser.add_argument("--width", type=int, default=16)
    parser.add_argument("--batch", type=int, default=4)
    parser.add_argument("--crop", type=int, default=32)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()

    grid_sample_snake = dense_ops.DenseOps.snake
    # the same check the tests make, on real sizes: both snakes give the same features
    torch.manual_seed(0)
    ops = dense_ops.DenseOps((args.crop,) * 3)
    y = torch.randn(args.batch, *ops.shape, 5 * 4)
    offsets = torch.randn(args.batch, *ops.shape, 2, 5) * 1.5
    diff = max(float((grid_sample_snake(ops, y, offsets, a) - gather_snake(ops, y, offsets, a))
                     .abs().max()) for a in range(3))
    print(f"snake outputs agree to {diff:.1e}")

    with tempfile.TemporaryDirectory() as out:
        cfg = TrainConfig(data=args.data, out=out, steps=[10, 0, 0], batch=args.batch,
                          crop=[args.crop, args.crop // 2 + 8, args.crop], threads=args.threads,
                          model={"width": args.width, "snake_kernel": 5})
        trainer = Trainer(cfg)
        batch = trainer.batch(0, 0)
        trainer.train_step(0, 0, batch)  # warm-up (allocator, mkldnn plans)
        times = {"gather": [], "grid_sample": []}
        for _ in range(args.repeat):
            for name, snake in (("gather", gather_snake), ("grid_sample", grid_sample_snake)):
                dense_ops.DenseOps.snake = snake
                start = time.perf_counter()
                trainer.train_step(0, 1, batch)
                times[name].append(time.perf_counter() - start)
        dense_ops.DenseOps.snake = grid_sample_snake
    base, new = (statistics.median(times[k]) for k in ("gather", "grid_sample"))
    print(f"width {args.width}, batch {args.batch} crops of {args.crop}^3, "
          f"{args.threads} threads, median of {args.repeat}:")
    print(f"  gather snake (baseline) {base:6.2f} s/step")
    print(f"  grid_sample snake       {new:6.2f} s/step   speed-up {base / new:.2f}x")


if __name__ == "__main__":
    main()
