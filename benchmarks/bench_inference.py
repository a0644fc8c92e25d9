"""Benchmark of AGNDC inference (band path), flat patches, dual contouring and the normal filter
against marching cubes.

Models: ``--models`` takes widths (a random-weight cascade with the default ``AGNDCConfig`` at that
width, e.g. 32 64) and/or ``shipped`` / ``undc`` (the packaged checkpoints with their own configs
and trained weights). For each model and grid size, in a fresh subprocess (so peak RSS is per run): AGNDC time per
scale and per stage (GDFEM / FDM / DFFM / CRPM, summed over scales), marching cubes of the same
lattice (scikit-image, level 0.5), the ratio, band rows at scale 0 and the peak RSS; then the
parameter count and safetensors file size of each model.

Usage: python benchmarks/bench_inference.py [--models shipped 32 64] [--sizes 32 64 128] [--seed 0]
       [--device cpu|cuda] [--threads N] [--repeat 1]
"""

import argparse
import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

from agndc_core.checkpoint import (count_parameters, default_checkpoint_path, load_checkpoint,
                                   save_checkpoint)
from agndc_core.contour import dual_contour
from agndc_core.flatpatches import flatten_patches
from agndc_core.labels import crossed_edges
from agndc_core.grid import pad_to_lattice
from agndc_core.inference import predict_lattice
from agndc_core.mc import marching_cubes_lattice
from agndc_core.nn import AGNDCCascade, AGNDCConfig
from agndc_core.nn.band_ops import surface_distance
from agndc_core.pipeline import filter_contoured_mesh
from agndc_core.shapes import generate_shape
from agndc_core.voxelize import voxelize

STAGES = ("gdfem", "fdm", "dffm", "crpm")


def cad_lattice(size: int, seed: int) -> np.ndarray:
    """A procedural CAD part voxelised at ``size`` on its longest side, padded to the lattice."""
    vertices, faces = generate_shape(seed)
    return pad_to_lattice(voxelize(vertices, faces, size).occupancy)


SHIPPED = {"shipped": "agndc", "undc": "undc"}


def build_model(spec: str):
    """The shipped checkpoint named by ``spec``, or a random-weight default cascade of that width."""
    if spec in SHIPPED:
        model, _ = load_checkpoint(default_checkpoint_path(SHIPPED[spec]))
        return model
    torch.manual_seed(0)
    return AGNDCCascade(AGNDCConfig(width=int(spec)))


def timed_model(spec: str, device: str):
    """A cascade whose scale and stage times accumulate in a dict."""
    model = build_model(spec).to(device).eval()
    times = {}

    def hook(key):
        def pre(module, args):
            if device == "cuda":
                torch.cuda.synchronize()
            times[key + "@"] = time.perf_counter()

        def post(module, args, out):
            if device == "cuda":
                torch.cuda.synchronize()
            times[key] = times.get(key, 0.0) + time.perf_counter() - times.pop(key + "@")
        return pre, post

    for s, net in enumerate(model.nets):
        for key, module in [(f"scale{s}", net)] + [(name, getattr(net, name)) for name in STAGES]:
            if module is not None:
                pre, post = hook(key)
                module.register_forward_pre_hook(pre)
                module.register_forward_hook(post)
    return model, times


def run_one(spec: str, size: int, seed: int, device: str, repeat: int) -> dict:
    lattice = cad_lattice(size, seed)
    model, times = timed_model(spec, device)
    best = None
    for _ in range(repeat):
        times.clear()
        start = time.perf_counter()
        vertex, _ = predict_lattice(model, lattice)
        network = time.perf_counter() - start
        # flat patches and the normal filter are part of every learned remesh (pipeline)
        pinned = np.zeros(vertex.shape, dtype=bool)
        vertex = flatten_patches(lattice, vertex, pinned=pinned)
        flattened = time.perf_counter() - start
        vertices, faces = dual_contour(vertex, crossed_edges(lattice), lattice)
        contoured = time.perf_counter() - start
        filter_contoured_mesh(vertices, faces, vertex, pinned)
        total = time.perf_counter() - start
        times["flat patches"] = flattened - network
        times["contour"] = contoured - flattened
        times["normal filter"] = total - contoured
        if best is None or total < best[0]:
            best = (total, dict(times))
    start = time.perf_counter()
    marching_cubes_lattice(lattice)
    mc = time.perf_counter() - start
    band_rows = int((surface_distance(lattice) <= model.config.band_radius).sum())
    return {"model": spec, "size": size, "shape": list(lattice.shape), "total": best[0],
            "times": best[1], "mc": mc, "band_rows": band_rows, "points": int(lattice.size),
            "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}


def model_size(spec: str) -> tuple[int, int]:
    model = build_model(spec)
    with tempfile.TemporaryDirectory() as tmp:
        path = save_checkpoint(model, Path(tmp) / "m", training={}, metrics={})
        return count_parameters(model), path.stat().st_size


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--models", nargs="+", default=["shipped", "32", "64"],
                        help="widths of random default cascades and/or 'shipped', 'undc'")
    parser.add_argument("--sizes", type=int, nargs="+", default=[32, 64, 128])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--threads", type=int, default=0, help="torch threads (0: default)")
    parser.add_argument("--repeat", type=int, default=1)
    parser.add_argument("--single", nargs=2, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.device == "cuda" and not torch.cuda.is_available():
        sys.exit("--device cuda: no CUDA device available")
    if args.threads:
        torch.set_num_threads(args.threads)
    if args.single:
        print(json.dumps(run_one(args.single[0], int(args.single[1]), args.seed, args.device, args.repeat)))
        return

    print(f"AGNDC band inference + dual contouring, CAD part seed {args.seed}, device "
          f"{args.device}, torch threads {args.threads or torch.get_num_threads()}")
    head = (f"{'model':>7} {'grid':>5} {'lattice':>13} {'band':>8} {'AGNDC s':>8} "
            f"{'scales 2/1/0 s':>17} {'GDFEM':>6} {'FDM':>6} {'DFFM':>6} {'CRPM':>6} "
            f"{'flat s':>6} {'DC s':>6} {'filter s':>8} {'MC s':>6} {'ratio':>6} {'peak MB':>8}")
    print(head)
    for spec in args.models:
        for size in args.sizes:
            cmd = [sys.executable, __file__, "--single", spec, str(size), "--seed",
                   str(args.seed), "--device", args.device, "--threads", str(args.threads),
                   "--repeat", str(args.repeat)]
            done = subprocess.run(cmd, capture_output=True, text=True)
            if done.returncode:
                print(f"{spec:>7} {size:>5} failed: {done.stderr.strip()[-300:]}")
                continue
            r = json.loads(done.stdout.strip().splitlines()[-1])
            t = r["times"]
            scales = "/".join(f"{t.get(f'scale{s}', 0):.2f}" for s in (2, 1, 0))
            stages = " ".join(f"{t.get(k, 0.0):6.2f}" for k in STAGES)
            print(f"{spec:>7} {size:>5} {'x'.join(map(str, r['shape'])):>13} "
                  f"{r['band_rows']:>8} {r['total']:8.2f} {scales:>17} {stages} "
                  f"{t['flat patches']:6.3f} {t['contour']:6.3f} {t['normal filter']:8.3f} "
                  f"{r['mc']:6.3f} {r['total'] / r['mc']:6.0f} {r['peak_rss_mb']:8.0f}",
                  flush=True)
    print()
    for spec in args.models:
        params, size = model_size(spec)
        print(f"{spec}: {params:,} parameters, safetensors {size / 2 ** 20:.1f} MiB")


if __name__ == "__main__":
    main()
