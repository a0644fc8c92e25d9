"""Speed of the stages between the network and the contouring (agndc_core/flatpatches.py): the
flat patches, the terraced planes and the stepped floors.

    .venv/bin/python benchmarks/bench_flat_stages.py [--sizes 64 128 192] [--repeat 3]

For a generated CAD part and a layered cap voxelised at each size, each stage runs on the
lattice as the pipeline runs it (with a ``pinned`` array), on surface nets vertices (the
stages' cost does not depend on what the network predicted, only on the patches). The
baselines, measured in the same run on the same grid: marching cubes and surface nets.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np


def best_of(repeat: int, func, *args, **kwargs) -> float:
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        func(*args, **kwargs)
        times.append(time.perf_counter() - start)
    return min(times)


def main() -> None:
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "research"))
    from layered_caps import layered_cap

    from agndc_core import flatpatches
    from agndc_core.grid import pad_to_lattice
    from agndc_core.mc import marching_cubes_lattice
    from agndc_core.study.shapes import cad_part
    from agndc_core.surfacenets import surface_nets_lattice
    from agndc_core.voxelize import voxelize

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[64, 128, 192])
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    print(f"load average {os.getloadavg()[0]:.2f}")

    stages = {"flat patches": flatpatches.flatten_patches,
              "terraced planes": flatpatches.fit_terraced_planes,
              "stepped floors": flatpatches.flatten_stepped_floors}
    for name, (vertices, faces) in (("CAD part", cad_part(7)), ("layered cap", layered_cap(22))):
        for size in args.sizes:
            lattice = pad_to_lattice(voxelize(vertices, faces, size).occupancy)
            vertex = surface_nets_lattice(lattice)
            mc_s = best_of(args.repeat, marching_cubes_lattice, lattice)
            nets_s = best_of(args.repeat, surface_nets_lattice, lattice)
            line = [f"{name} {size}³ ({lattice.size / 1e6:.2f} M points): marching cubes "
                    f"{mc_s:.3f} s, surface nets {nets_s:.3f} s"]
            for stage, run in stages.items():
                seconds = best_of(args.repeat, run, lattice, vertex,
                                  pinned=np.zeros(vertex.shape, dtype=bool))
                line.append(f"{stage} {seconds:.3f} s ({seconds / mc_s:.2f}x MC)")
            print("; ".join(line), flush=True)
    print(f"load average {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
