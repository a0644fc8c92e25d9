"""Worst-case cancel latency of every stage of a mesh remesh: the longest gap between two
cancellation checks.

A run stops at its next check after Esc (``remesh(..., cancel=)`` calls ``cancel.is_set()``
between and inside its stages), so the longest gap between two checks within a stage is the
longest a user can wait there. One uncancelled run per method records the time of every check
and the stage it falls in (from the progress messages); the Chamfer distance to the source (the
Blender report's "distance" step, ``metrics.chamfer_distance``) is recorded the same way. The
baseline printed beside each stage is the stage's own duration: a stage without inner checks
waits its whole length.

Input: a generated CAD part, its surface subdivided to about ``--triangles`` triangles (a
dense sculpt-like mesh: the voxeliser's and Sharp's cost grow with the triangle count).

Usage: python benchmarks/bench_cancel_stages.py [--triangles 1000000] [--res 128]
       [--methods agndc sharp] [--threads 2]
"""

from __future__ import annotations

import argparse
import os
import time
from collections import defaultdict


class CheckRecorder:
    """A cancel object that is never set and records when (and in which stage) it is asked."""

    def __init__(self):
        self.stage = "start"
        self.times: list[tuple[float, str]] = []

    def is_set(self) -> bool:
        self.times.append((time.perf_counter(), self.stage))
        return False

    def progress(self, fraction: float, message: str) -> None:
        self.stage = message.split(" (")[0].split(" tile")[0]
        self.is_set()  # a progress report is also a moment the run can be stopped at

    def check(self) -> None:
        self.is_set()

    def gaps(self, start: float, end: float) -> dict:
        """{stage: (longest gap between checks, seconds in the stage)}."""
        marks = [(start, "start"), *self.times, (end, "end")]
        longest, total = defaultdict(float), defaultdict(float)
        for (t0, _), (t1, stage) in zip(marks, marks[1:]):
            longest[stage] = max(longest[stage], t1 - t0)
            total[stage] += t1 - t0
        return {k: (longest[k], total[k]) for k in longest}


def dense_part(triangles: int):
    """A generated CAD part whose faces are split 4-to-1 until it has >= ``triangles``."""
    import trimesh

    from agndc_core.study.shapes import cad_part

    vertices, faces = cad_part(7)
    while len(faces) < triangles:
        vertices, faces = trimesh.remesh.subdivide(vertices, faces)
    return vertices, faces


def main() -> None:
    from agndc_core import metrics
    from agndc_core.pipeline import remesh_mesh

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--triangles", type=int, default=1_000_000)
    parser.add_argument("--res", type=int, default=128)
    parser.add_argument("--methods", nargs="+", default=["agndc", "sharp"])
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args()
    vertices, faces = dense_part(args.triangles)
    print(f"cancel latency: {len(faces):,} triangles at {args.res} voxels, {os.cpu_count()} "
          f"cores, load {os.getloadavg()[0]:.2f}")
    for method in args.methods:
        recorder = CheckRecorder()
        start = time.perf_counter()
        result = remesh_mesh(vertices, faces, resolution=args.res, method=method,
                             threads=args.threads, progress=recorder.progress, cancel=recorder)
        recorder.stage = "distance to the source"
        recorder.check()
        metrics.chamfer_distance(result.vertices, result.faces, vertices, faces,
                                 n_samples=30_000, check=recorder.check)
        end = time.perf_counter()
        print(f"\n{method}: {end - start:.2f} s in all, load {os.getloadavg()[0]:.2f}")
        print(f"  {'stage':32s} {'longest wait':>12s} {'stage time':>11s}")
        for stage, (longest, total) in recorder.gaps(start, end).items():
            print(f"  {stage:32s} {longest:11.2f}s {total:10.2f}s")


if __name__ == "__main__":
    main()
