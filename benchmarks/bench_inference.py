"""Benchmark of the learned remesh, end to end in-process, against marching cubes and surface nets.

For each input, in a fresh subprocess (so peak RSS is per input): ``pipeline.remesh`` of the same
``VoxelGrid`` with marching cubes, surface nets, the shipped AGNDC (numpy runtime: network, flat
patches, dual contouring, normal filter) and its distilled version (``agndc_fast``), the best of
``--repeat`` runs each, with the ratio of AGNDC to MC and to surface nets, the pipeline's stage
times, the network's time per scale and per module (GDFEM's convolutions, LWSA, DSConv, FDM,
DFFM, CRPM, band set-up), the numpy runtime's convolution throughput, and, where torch is
installed, the same network by torch's band path (``--torch``) as the reference runtime. The
machine's load average is printed with every row; ``--load N`` starts N busy processes for the
duration (a shared machine: a Blender user's UI and other programs).

Inputs: ``64``, ``128``, ``256`` (a generated CAD part voxelised with that many voxels on its
longest side), ``brain`` (a folded 197x233x189 mask of the size of an MNI152 white-matter mask,
generated: a smoothed random field inside an ellipsoid), ``mesh:PATH@RES`` (a mesh file).

Usage: python benchmarks/bench_inference.py [--inputs 64 128 256 brain] [--threads 2]
       [--repeat 2] [--load 0] [--torch]
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import resource
import subprocess
import sys
import time
from collections import defaultdict

import numpy as np

STAGES = ("voxelise", "predict", "flat patches", "source bounds", "dual contouring",
          "normal filter")
#: the network's modules timed inside ``predict`` (``runtime.network.Network`` methods)
MODULES = ("gdfem", "lwsa", "dsconv", "fdm", "dffm", "crpm")


def make_grid(spec: str):
    """The VoxelGrid of one input spec (see the module docstring)."""
    from agndc_core.grid import VoxelGrid
    from agndc_core.voxelize import voxelize

    if spec == "brain":
        from scipy import ndimage

        rng = np.random.default_rng(0)
        shape = (197, 233, 189)
        field = ndimage.gaussian_filter(rng.standard_normal(shape).astype(np.float32), 3.0)
        axes = [np.linspace(-1, 1, n, dtype=np.float32) for n in shape]
        x, y, z = np.meshgrid(*axes, indexing="ij")
        r = np.sqrt((x / 0.85) ** 2 + (y / 0.9) ** 2 + (z / 0.8) ** 2)
        occupancy = (r < 0.95) & (field > -0.02 + 0.5 * np.clip(r - 0.6, 0, None))
        return VoxelGrid(ndimage.binary_opening(occupancy, iterations=1))
    if spec.startswith("mesh:"):
        from agndc_core.gridio import load_mesh

        path, res = spec[5:].rsplit("@", 1)
        vertices, faces = load_mesh(path)
        return voxelize(vertices, faces, int(res))
    from agndc_core.study.shapes import generate_shape

    vertices, faces = generate_shape(0)
    return voxelize(vertices, faces, int(spec))


def timed_modules(network) -> dict:
    """Accumulate the seconds of the network's modules and band ops (outermost call only)."""
    from agndc_core.runtime import band

    times: dict = defaultdict(float)
    depth = {"n": 0}

    def wrap(owner, name, label):
        original = getattr(owner, name)

        def timed(*args, **kwargs):
            start = time.perf_counter()
            try:
                return original(*args, **kwargs)
            finally:
                times[label] += time.perf_counter() - start

        setattr(owner, name, timed)

    for name in MODULES:
        wrap(type(network), name, name)
    wrap(band.Band, "conv", "band conv")
    wrap(band.Band, "snake", "band snake")
    wrap(band.Band, "windows", "window attention")
    wrap(band, "scale_band", "band set-up")
    del depth
    return times


def run_one(spec: str, threads: int, repeat: int, with_torch: bool) -> dict:
    from agndc_core.checkpoint import default_checkpoint_path
    from agndc_core.pipeline import load_model, remesh

    grid = make_grid(spec)
    row = {"input": spec, "shape": list(grid.occupancy.shape),
           "occupied": int(grid.occupancy.sum()), "load_before": os.getloadavg()[0]}
    network = load_model(default_checkpoint_path("agndc"))
    module_times = timed_modules(network)
    for method in ("mc", "surfacenets", "agndc", "agndc_fast"):
        best = None
        for _ in range(repeat):
            module_times.clear()
            start = time.perf_counter()
            result = remesh(grid, method=method, threads=threads)
            seconds = time.perf_counter() - start
            if best is None or seconds < best[0]:
                best = (seconds, dict(result.timings), dict(module_times), len(result.faces))
        row[method] = {"seconds": best[0], "stages": best[1], "modules": best[2],
                       "faces": best[3]}
    if with_torch:
        row["torch"] = torch_network_seconds(grid, threads, repeat)
    row["peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    row["load_after"] = os.getloadavg()[0]
    return row


def torch_network_seconds(grid, threads: int, repeat: int) -> float | None:
    """The same network by torch's band path (the reference runtime), best of ``repeat``."""
    try:
        import torch
    except ImportError:
        return None
    from agndc_core.checkpoint import default_checkpoint_path, load_checkpoint
    from agndc_core.grid import pad_to_lattice
    from agndc_core.inference import predict_lattice

    torch.set_num_threads(threads)
    model, _ = load_checkpoint(default_checkpoint_path("agndc"))
    lattice = pad_to_lattice(grid.occupancy)
    best = float("inf")
    for _ in range(repeat):
        start = time.perf_counter()
        predict_lattice(model, lattice)
        best = min(best, time.perf_counter() - start)
    return best


def _busy(stop) -> None:
    x = 0
    while not stop.is_set():
        for _ in range(100000):
            x += 1


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--inputs", nargs="+", default=["64", "128", "256", "brain"])
    parser.add_argument("--threads", type=int, default=0, help="network threads (0: all cores)")
    parser.add_argument("--repeat", type=int, default=2)
    parser.add_argument("--load", type=int, default=0,
                        help="busy processes competing for the cores during the runs")
    parser.add_argument("--torch", action="store_true",
                        help="also time torch's band path on the same lattice (reference)")
    parser.add_argument("--json", help="also write the rows to this file")
    parser.add_argument("--single", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.single:
        print(json.dumps(run_one(args.single, args.threads, args.repeat, args.torch)))
        return

    stop = multiprocessing.Event()
    burners = [multiprocessing.Process(target=_busy, args=(stop,), daemon=True)
               for _ in range(args.load)]
    for burner in burners:
        burner.start()
    print(f"AGNDC remesh end to end (numpy runtime), {os.cpu_count()} cores, network threads "
          f"{args.threads or 'all'}, competing busy processes {args.load}, best of {args.repeat}")
    rows = []
    try:
        for spec in args.inputs:
            command = [sys.executable, __file__, "--single", spec, "--threads",
                       str(args.threads), "--repeat", str(args.repeat)]
            command += ["--torch"] if args.torch else []
            done = subprocess.run(command, capture_output=True, text=True)
            if done.returncode:
                print(f"{spec}: failed: {done.stderr.strip()[-500:]}")
                continue
            rows.append(json.loads(done.stdout.strip().splitlines()[-1]))
            print_row(rows[-1])
    finally:
        stop.set()
        for burner in burners:
            burner.join()
    if args.json:
        with open(args.json, "w") as handle:
            json.dump(rows, handle, indent=1)


def print_row(r: dict) -> None:
    a, mc, sn = r["agndc"], r["mc"]["seconds"], r["surfacenets"]["seconds"]
    shape = "x".join(map(str, r["shape"]))
    torch_s = r.get("torch")
    print(f"\n{r['input']} ({shape}, {r['occupied']:,} voxels; load {r['load_before']:.2f} -> "
          f"{r['load_after']:.2f}; peak RSS {r['peak_rss_mb']:.0f} MB)")
    print(f"  AGNDC {a['seconds']:.2f} s = {a['seconds'] / mc:.0f}x MC ({mc:.3f} s), "
          f"{a['seconds'] / sn:.1f}x surface nets ({sn:.3f} s); {a['faces']:,} faces"
          + (f"; network by torch {torch_s:.2f} s" if torch_s else ""))
    fast = r["agndc_fast"]
    print(f"  the distilled cascade (agndc_fast) {fast['seconds']:.2f} s = "
          f"{fast['seconds'] / mc:.0f}x MC, {a['seconds'] / fast['seconds']:.2f}x faster")
    print("  stages: " + ", ".join(f"{k} {v:.2f}" for k, v in a["stages"].items()))
    print("  network: " + ", ".join(f"{k} {v:.2f}" for k, v in sorted(
        a["modules"].items(), key=lambda kv: -kv[1])))


if __name__ == "__main__":
    main()
