"""Network time of cheaper student architectures against the shipped cascade's, in one run.

Speed does not depend on the weights, so every architecture runs with random weights on the
same lattice in the numpy runtime (``predict_lattice``, band inference, vertices only, as
``remesh`` runs it); the shipped architecture (ω16, snake kernel 5, band radius 4) is the
baseline, and each row prints its ratio to it. What a student must keep of the shipped model's
quality is measured by training it (docs/experiments/student.md).

Usage: python benchmarks/bench_students.py [--inputs 64 128] [--threads 2] [--repeat 2]
       [--students plain w8 w8plain ...]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))  # bench_inference's inputs

#: the shipped cascade's architecture (agndc_core/weights/agndc.json)
SHIPPED = dict(width=16, snake_kernel=5, band_radius=4, surface_nets_prior=False)
#: candidate students: changes to the shipped architecture
STUDENTS = {
    "shipped": {},
    "w8": dict(width=8),
    "nosnake": dict(use_snake=False),
    "noattention": dict(use_attention=False),
    "plain": dict(use_snake=False, use_attention=False),
    "w8plain": dict(width=8, use_snake=False, use_attention=False),
    "w8plain_r2": dict(width=8, use_snake=False, use_attention=False, band_radius=2),
    "w12plain_r3": dict(width=12, use_snake=False, use_attention=False, band_radius=3),
    # plain, and each scale adds its DFFM output to the up-sampled coarser prediction (no CRPM)
    "plain_nocrpm": dict(use_snake=False, use_attention=False, use_crpm=False),
    # plain, and each scale adds the up-sampled coarser prediction unfused (no DFFM, no CRPM)
    "plain_nofuse": dict(use_snake=False, use_attention=False, use_dffm=False, use_crpm=False),
    # one scale of plain convolutions: the UNDC architecture (agndc_core/weights/undc.json)
    "undc": dict(levels=0, use_snake=False, use_attention=False, use_dffm=False,
                 use_crpm=False, surface_nets_prior=True),
}


def network_seconds(config, lattice, repeat: int) -> float:
    import torch

    from agndc_core.inference import predict_lattice
    from agndc_core.nn.agdrnet import AGNDCCascade
    from agndc_core.runtime.network import Network

    torch.manual_seed(0)
    network = Network.from_torch(AGNDCCascade(config).eval())
    best = float("inf")
    for _ in range(repeat):
        start = time.perf_counter()
        predict_lattice(network, lattice, edges=False)
        best = min(best, time.perf_counter() - start)
    return best


def main() -> None:
    from bench_inference import make_grid

    from agndc_core.grid import pad_to_lattice
    from agndc_core.nn.config import AGNDCConfig
    from agndc_core.runtime.parallel import set_threads

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--inputs", nargs="+", default=["64", "128"])
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--repeat", type=int, default=2)
    parser.add_argument("--students", nargs="+", default=list(STUDENTS))
    args = parser.parse_args()
    set_threads(args.threads)
    for spec in args.inputs:
        lattice = pad_to_lattice(make_grid(spec).occupancy)
        print(f"\n{spec}: lattice {'x'.join(map(str, lattice.shape))}, {args.threads} threads, "
              f"load {os.getloadavg()[0]:.2f}")
        baseline = network_seconds(AGNDCConfig(**SHIPPED), lattice, args.repeat)
        print(f"  {'shipped':12s} {baseline:7.3f} s  1.00x")
        for name in args.students:
            if name == "shipped":
                continue
            config = AGNDCConfig(**{**SHIPPED, **STUDENTS[name]})
            seconds = network_seconds(config, lattice, args.repeat)
            print(f"  {name:12s} {seconds:7.3f} s  {seconds / baseline:.2f}x  "
                  f"(load {os.getloadavg()[0]:.2f})", flush=True)


if __name__ == "__main__":
    main()
