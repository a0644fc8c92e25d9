"""Geometric accuracy on analytic solids (the geometric quality targets), every method side by side.

    .venv/bin/python benchmarks/bench_geometry.py [--res 64] [--checkpoint agndc=PATH ...]
        [--no-flat-patches] [--no-normal-filter] [--source-bounds]

An axis-aligned box (flatness, and RMS from the true planes), the box rotated 20/35 deg (face
RMS, worst corner) and a sphere (radial RMS), errors in voxels; ``agndc_core/study/solids.py``
defines every number and holds the targets. The methods see the grid alone; ``--source-bounds`` also
gives them the solid's bounding box (``remesh(source_bounds=True)``, what mesh input gets by
default; marching cubes and its smoothing ignore it). Marching cubes is the time ratio's
baseline, measured in the same run. The two oracles contour the solid's exact labels
(``oracle_binary`` with the depth of axis-aligned faces a binary grid cannot hold put back): what
one vertex per cell can reach. At 64³ two corners of the rotated box lie in cells with no
occupied corner point, so no vertex of their own; the oracle's worst corner is 0.555 voxel there.
"""

from __future__ import annotations

import argparse

from agndc_core.errors import AGNDCError
from agndc_core.study.solids import TARGETS, measure

METHODS = ("mc", "mc_taubin", "surfacenets", "undc", "agndc", "oracle_binary", "oracle")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--res", type=int, default=64)
    parser.add_argument("--checkpoint", action="append", default=[], metavar="METHOD=PATH")
    parser.add_argument("--no-flat-patches", dest="flat_patches", action="store_false",
                        help="learned methods: the network's raw vertices (pipeline.remesh)")
    parser.add_argument("--no-normal-filter", dest="normal_filter", action="store_false",
                        help="learned methods: the contoured mesh unfiltered (pipeline.remesh)")
    parser.add_argument("--source-bounds", action="store_true",
                        help="dual methods also get the solid's bounding box (pipeline.remesh)")
    args = parser.parse_args()
    checkpoints = dict(item.split("=", 1) for item in args.checkpoint)

    print(f"{args.res}³, errors in voxels; targets: "
          + ", ".join(f"{name} <= {value}" for name, value in TARGETS.items()))
    print(f"{'method':13s} {'box flat':>9s} {'box RMS':>8s} {'rot RMS':>8s} {'corner':>7s} "
          f"{'sphere':>7s} {'s':>6s}")
    baseline = None
    for method in METHODS:
        try:
            e = measure(method, args.res, checkpoint=checkpoints.get(method), threads=2,
                        flat_patches=args.flat_patches, normal_filter=args.normal_filter,
                        source_bounds=args.source_bounds)
        except (AGNDCError, OSError) as exc:  # a missing checkpoint: report and go on
            print(f"{method:13s} failed: {exc}")
            continue
        baseline = e["seconds"] if baseline is None else baseline
        print(f"{method:13s} {e['flatness']:9.3f} {e['box_rms']:8.3f} {e['rotated_rms']:8.3f} "
              f"{e['corner']:7.3f} {e['sphere']:7.3f} {e['seconds']:6.2f}  "
              f"({e['seconds'] / baseline:.0f}x mc time)")


if __name__ == "__main__":
    main()
