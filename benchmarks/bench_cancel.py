"""How quickly does AGNDC inference stop on cancel, and how often does it report progress?

A worker thread runs ``predict_lattice`` (shipped weights, the CAD part ``shapes.cad_part(7)``
voxelised at ``--res``) the way the Blender operator does; the main thread records every progress
call, sets the cancel event after ``--cancel-after`` seconds and measures the time until the
worker has raised ``CancelledError`` and ended. A second, uncancelled run gives the full time
and the gaps between progress reports. Baseline in the same run: the same inference without
progress or cancel arguments (the cost of the per-call checks).

Usage: python benchmarks/bench_cancel.py [--res 155] [--threads 1] [--cancel-after 8]
"""

import argparse
import threading
import time

import numpy as np
import torch

from agndc_core.errors import CancelledError
from agndc_core.grid import pad_to_lattice
from agndc_core.inference import predict_lattice
from agndc_core.pipeline import _default_checkpoint, load_model
from agndc_core.study.shapes import cad_part
from agndc_core.voxelize import voxelize


def run(model, lattice, cancel_after: float | None):
    """(seconds to stop after cancel or None, full seconds, [(time, fraction)])."""
    cancel, seen, result = threading.Event(), [], {}
    start = time.perf_counter()

    def work():
        try:
            predict_lattice(model, lattice, cancel=cancel,
                            progress=lambda f, m: seen.append((time.perf_counter() - start, f)))
        except CancelledError:
            result["cancelled"] = time.perf_counter()
        result["end"] = time.perf_counter()

    thread = threading.Thread(target=work)
    thread.start()
    stop = None
    if cancel_after is not None:
        thread.join(cancel_after)
        asked = time.perf_counter()
        cancel.set()
        thread.join()
        stop = result["end"] - asked if "cancelled" in result else None
    thread.join()
    return stop, result["end"] - start, seen


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--res", type=int, default=155)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--cancel-after", type=float, default=8.0)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    vertices, faces = cad_part(7)
    lattice = pad_to_lattice(voxelize(vertices, faces, args.res).occupancy)
    model = load_model(_default_checkpoint("agndc"))
    start = time.perf_counter()
    predict_lattice(model, lattice)
    plain = time.perf_counter() - start
    _, full, seen = run(model, lattice, None)
    times = np.array([t for t, _ in seen])
    fractions = np.array([f for _, f in seen])
    gaps = np.diff(np.concatenate([[0.0], times, [full]]))
    print(f"lattice {lattice.shape}, {args.threads} thread(s)")
    print(f"inference without progress/cancel: {plain:.2f} s; with: {full:.2f} s "
          f"(ratio {full / plain:.3f})")
    print(f"progress calls: {len(seen)}, longest gap {gaps.max():.2f} s, median "
          f"{np.median(gaps):.2f} s, monotone: {bool(np.all(np.diff(fractions) >= 0))}")
    for share in (0.25, 0.5, 0.75):
        at = np.searchsorted(times, share * full)
        value = fractions[min(at, len(fractions) - 1)]
        print(f"  at {share:.0%} of the time the bar shows {value:.0%}")
    stops = [run(model, lattice, args.cancel_after)[0] for _ in range(3)]
    print("stop after cancel (s): " + ", ".join("not cancelled" if s is None else f"{s:.3f}"
                                                for s in stops))


if __name__ == "__main__":
    main()
