"""One job of a batch: what a worker process does with one input file (``batch.py`` runs the
jobs locally, ``batch_dask.py`` on a Dask cluster; both import this module, not each other)."""

from __future__ import annotations

import os
import socket
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .colors import result_colors
from .errors import AGNDCError
from .gridio import save_mesh
from .options import RemeshOptions
from .pipeline import MESH_ONLY_METHODS, remesh, remesh_file

_PREPARED: dict = {}  # per process: the (options, threads) a worker was prepared for


@dataclass(frozen=True)
class Job:
    """One input file and the output file it becomes (absolute paths, so any worker can use
    them on a shared filesystem)."""

    input: str
    output: str



def run_job(job: Job, options: RemeshOptions) -> dict:
    """Remesh one file and write its output; a row for batch.csv. Bad input is a failed row.

    The output is written through ``gridio.save_mesh`` (temporary name, then an atomic rename).
    KeyboardInterrupt and other BaseExceptions propagate (nothing partial is left behind).
    """
    start = time.perf_counter()
    row = {"input": job.input, "output": job.output, "method": options.method}
    try:
        result = remesh_file(job.input, options,
                             threads=options.threads or _PREPARED.get("threads"))
        Path(job.output).parent.mkdir(parents=True, exist_ok=True)
        save_mesh(result.vertices, result.faces, job.output, **result_colors(result))
        row.update(grid="x".join(str(n) for n in result.grid.shape), faces=len(result.faces),
                   vertices=len(result.vertices), status="ok", error="")
    except AGNDCError as exc:
        row.update(status="failed", error=str(exc))
    except Exception as exc:  # a bug or a library's surprise: still only this file's failure
        row.update(status="failed", error=f"{type(exc).__name__}: {exc}")
    row.update(seconds=f"{time.perf_counter() - start:.3f}", **_process_stats())
    return row


def failed_row(job: Job, options: RemeshOptions, error: str) -> dict:
    """The row of a job that ended without its own row (its worker died)."""
    return {"input": job.input, "output": job.output, "method": options.method,
            "status": "failed", "error": error}


def prepare_worker(options: RemeshOptions, threads: int | None) -> None:
    """Once per worker process: the network's share of the cores, and a warm-up remesh of a 2x2x2
    grid, which imports what the method needs and loads its network into ``pipeline``'s
    per-process model cache, so no job loads or receives it again (and a job's seconds are its
    own work)."""
    key = (options, threads)
    if _PREPARED.get("key") == key:
        return
    if options.method not in MESH_ONLY_METHODS:  # those need a mesh: nothing to warm up
        remesh(np.ones((2, 2, 2), dtype=bool), method=options.method,
               checkpoint=options.checkpoint, device=options.device)
    _PREPARED["key"], _PREPARED["threads"] = key, threads


def _process_stats() -> dict:
    """Peak resident memory (MB) of this process so far ("" where the OS does not say), and
    which process this is (host:pid)."""
    return {"peak_rss_mb": _peak_rss_mb(), "worker": f"{socket.gethostname()}:{os.getpid()}"}


def _peak_rss_mb() -> str:
    # Linux: VmHWM is this process image's own peak; getrusage's ru_maxrss would also count
    # the parent's memory at fork, which a spawned worker inherits across exec
    try:
        with open("/proc/self/status", encoding="ascii") as status:
            for line in status:
                if line.startswith("VmHWM:"):
                    return f"{int(line.split()[1]) / 1024:.0f}"  # kB
    except OSError:
        pass
    try:
        import resource  # POSIX only
    except ImportError:
        return ""
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss  # macOS: bytes, else KiB
    return f"{peak / (1 << 20 if sys.platform == 'darwin' else 1024):.0f}"


