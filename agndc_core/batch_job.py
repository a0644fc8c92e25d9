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
from .labelmaps import check_grid_method, label_output_path, load_label_map, remesh_label
from .options import RemeshOptions
from .pipeline import MESH_ONLY_METHODS, remesh, remesh_file

_PREPARED: dict = {}  # per process: the (options, threads) a worker was prepared for


@dataclass(frozen=True)
class Job:
    """One input file and the output file it becomes (absolute paths, so any worker can use
    them on a shared filesystem).

    A per-label job (``per_label``) reads the input as a label map and writes one mesh per
    label beside ``output``, named as ``agndc remesh --per-label`` names them
    (``labelmaps.label_output_path``: ``out/seg.ply`` -> ``out/seg_label-3.ply``); ``output``
    itself is then never written. ``labels``: only these (empty: every label in the file);
    ``overwrite``: also redo the labels whose outputs are up to date (the rest are skipped
    label by label, since which labels a file holds is known only once it is read).
    """

    input: str
    output: str
    per_label: bool = False
    labels: tuple[int, ...] = ()
    overwrite: bool = False

    def known_outputs(self) -> list[str] | None:
        """The files this job writes, when they are known without reading the input (None: a
        per-label job over every label)."""
        if not self.per_label:
            return [self.output]
        if not self.labels:
            return None
        return [self.label_output(label) for label in self.labels]

    def label_output(self, label: int) -> str:
        return str(label_output_path(self.output, label))


def is_current(source, output) -> bool:
    """True when ``output`` exists and is at least as new as ``source`` (a batch skips it)."""
    try:
        return os.stat(output).st_mtime_ns >= os.stat(source).st_mtime_ns
    except OSError:
        return False


def run_job(job: Job, options: RemeshOptions) -> list[dict]:
    """Remesh one file and write its output(s); the job's rows for batch.csv: one for a file,
    one per label for a per-label job. Bad input is a failed row, a label that fails is that
    label's failed row (the other labels are still written).

    Outputs are written through ``gridio.save_mesh`` (temporary name, then an atomic rename).
    KeyboardInterrupt and other BaseExceptions propagate (nothing partial is left behind).
    """
    options = RemeshOptions.of(options, threads=options.threads or _PREPARED.get("threads"))
    if job.per_label:
        return _label_rows(job, options)
    start = time.perf_counter()
    row = _row(job.input, job.output, "", options)
    try:
        row.update(_write(remesh_file(job.input, options), job.output))
    except Exception as exc:
        row.update(_failure(exc))
    return [_finish(row, start)]


def _label_rows(job: Job, options: RemeshOptions) -> list[dict]:
    """The rows of a per-label job, one per label in the order asked for (ascending labels
    when all are meshed). The first row's seconds include reading the file."""
    start = time.perf_counter()
    try:
        check_grid_method(options.method)
        volume = load_label_map(job.input)
        wanted = volume.wanted(job.labels)
    except Exception as exc:  # the file cannot be read as a label map: one row says why
        return [_finish({**_row(job.input, job.output, "", options), **_failure(exc)}, start)]
    rows = []
    for label in wanted:
        output = job.label_output(label)
        row = _row(job.input, output, label, options)
        if label not in volume.labels():
            row.update(status="failed", error=volume.missing_message([label]))
        elif not job.overwrite and is_current(job.input, output):
            row.update(status="skipped", error="")
        else:
            try:
                row.update(_write(remesh_label(volume, label, options), output))
            except Exception as exc:
                row.update(_failure(exc))
        rows.append(_finish(row, start))
        start = time.perf_counter()
    return rows


def _row(source: str, output: str, label, options: RemeshOptions) -> dict:
    return {"input": source, "output": output, "label": label, "method": options.method}


def _write(result, output: str) -> dict:
    """Save a remesh result at ``output``; its columns of batch.csv."""
    Path(output).parent.mkdir(parents=True, exist_ok=True)
    save_mesh(result.vertices, result.faces, output, **result_colors(result))
    return {"grid": "x".join(str(n) for n in result.grid.shape), "faces": len(result.faces),
            "vertices": len(result.vertices), "status": "ok", "error": ""}


def _failure(exc: Exception) -> dict:
    """A failed row's columns: an ``AGNDCError`` says what is wrong with the input; anything
    else (a bug, a library's surprise) is still only this file's or label's failure."""
    error = str(exc) if isinstance(exc, AGNDCError) else f"{type(exc).__name__}: {exc}"
    return {"status": "failed", "error": error}


def _finish(row: dict, start: float) -> dict:
    return {**row, "seconds": f"{time.perf_counter() - start:.3f}", **_process_stats()}


def failed_row(job: Job, options: RemeshOptions, error: str) -> dict:
    """The row of a job that ended without its own rows (its worker died)."""
    return {**_row(job.input, job.output, "", options), "status": "failed", "error": error}


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


