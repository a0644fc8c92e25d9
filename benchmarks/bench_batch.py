"""Batch throughput: N generated grids remeshed by ``batch.remesh_many`` with 1 worker, with the
local process pool and with a Dask ``LocalCluster``, in one run.

The baseline is ``--workers 1``: the jobs run one after another in this process, torch using
every core (what ``agndc batch --workers 1`` does). The pool and the cluster start ``--workers``
processes with ``cores // workers`` torch threads each. Wall times include starting the pool or
the cluster, as a user sees them. Peak memory is each worker process's peak resident set
(``getrusage``, returned in its rows). All outputs are checked to be the same meshes across the
three runs: the same faces, vertices equal up to float rounding (torch's sums differ in the last
bits between 2 threads in one process and 1 thread per worker).

Usage: python benchmarks/bench_batch.py [--n 16] [--res 48] [--workers 2] [--method agndc]
"""

import argparse
import multiprocessing
import os
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from agndc_core.batch import remesh_many
from agndc_core.gridio import load_mesh
from agndc_core.runtime.parallel import default_threads


def make_grids(folder: Path, n: int, res: int) -> None:
    """``n`` procedural shapes (``shapes.generate_shape``) voxelised at ``res`` as .npy files."""
    from agndc_core.gridio import save_grid
    from agndc_core.study.shapes import generate_shape
    from agndc_core.voxelize import voxelize

    for seed in range(n):
        save_grid(voxelize(*generate_shape(seed), res), folder / f"shape{seed:03d}.npy")


def run(name: str, folder: Path, out: Path, **kwargs) -> dict:
    start = time.perf_counter()
    rows = remesh_many([folder], out, overwrite=True, **kwargs)
    wall = time.perf_counter() - start
    failed = [r for r in rows if r["status"] != "ok"]
    assert not failed, failed
    peaks = {}
    for row in rows:  # a row carries its process's peak so far: the last one is the peak
        peaks[row["worker"]] = max(peaks.get(row["worker"], 0.0), float(row["peak_rss_mb"]))
    return {"name": name, "wall": wall, "rows": rows, "peaks": peaks,
            "job_seconds": sum(float(r["seconds"]) for r in rows) / len(rows)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=16, help="grids")
    parser.add_argument("--res", type=int, default=48, help="voxels on each grid's longest side")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--method", default="agndc")
    args = parser.parse_args()

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        grids = tmp / "grids"
        grids.mkdir()
        # generated in a child process, so this process's peak memory is the batch's own
        context = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(1, mp_context=context) as pool:
            pool.submit(make_grids, grids, args.n, args.res).result()
        common = dict(method=args.method)
        results = [
            run("1 worker (serial)", grids, tmp / "serial", workers=1, **common),
            run(f"local pool x{args.workers}", grids, tmp / "pool", workers=args.workers,
                **common),
            run(f"dask LocalCluster x{args.workers}", grids, tmp / "dask",
                workers=args.workers, engine="dask", **common),
        ]
        worst = 0.0
        for result in results[1:]:  # the same meshes (up to float rounding of the network)
            for row in result["rows"]:
                got_v, got_f = load_mesh(row["output"])
                want_v, want_f = load_mesh(tmp / "serial" / Path(row["output"]).name)
                assert np.array_equal(got_f, want_f) and got_v.shape == want_v.shape
                worst = max(worst, float(np.abs(got_v - want_v).max()))

    load = ", ".join(f"{x:.1f}" for x in os.getloadavg())
    print(f"{args.n} grids at {args.res}^3, method {args.method}, {default_threads()} cores, "
          f"load average {load} (1, 5, 15 min)")
    base = results[0]["wall"]
    print(f"{'engine':<24} {'wall s':>7} {'files/s':>8} {'speed-up':>8} {'s/job':>6}  "
          "peak RSS per worker (MB)")
    for r in results:
        peaks = ", ".join(f"{v:.0f}" for v in sorted(r["peaks"].values()))
        print(f"{r['name']:<24} {r['wall']:7.2f} {args.n / r['wall']:8.2f} "
              f"{base / r['wall']:7.2f}x {r['job_seconds']:6.2f}  {peaks}")
    print(f"outputs: the same faces across the three engines, vertices within {worst:.1e} "
          "voxels")


if __name__ == "__main__":
    main()
