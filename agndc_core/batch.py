"""Batch remeshing of many files: ``remesh_many``, behind ``agndc batch`` (and, for what needs no
Blender object, the Blender batch script).

    INPUTS --discover_inputs--> jobs --engine: run_job per file--> rows --> OUTDIR/batch.csv

* **Inputs.** Files (grids ``gridio.GRID_EXTENSIONS``, meshes ``gridio.MESH_EXTENSIONS``),
  folders (searched recursively by extension; the output folder is never searched) and
  manifests (``.txt``/``.lst``: one path a line, ``#`` comments; ``.csv``: a first column of
  paths, or an ``input`` column and an optional ``output`` column). Relative manifest paths are
  relative to the manifest's folder. ``dir/sub/x.stl`` becomes ``OUTDIR/sub/x.<format>``.
* **One job** (``run_job``) is ``pipeline.remesh_file`` (the code path of ``agndc remesh``) and
  ``gridio.save_mesh``, which writes ``name.tmp-<pid>.<ext>`` and renames it into place, so an
  output file is always complete. It never raises for a bad input: the error becomes a row.
* **Per label** (``per_label``, ``labels``). Each input is read as a label map and every chosen
  label becomes its own output, named as ``agndc remesh --per-label`` names it
  (``labelmaps.label_output_path``: ``OUTDIR/sub/seg_label-3.ply``), and its own row; a label
  that fails (or is not in the file) is its own failed row, the file's other labels are still
  written. A job is still one file, so a label map is read once, whatever its label count.
* **Resumable.** An output at least as new as its input is skipped (a "skipped" row that keeps
  the previous run's numbers) unless ``overwrite``; per label, each label's output on its own.
  Rows are appended to ``batch.csv`` and flushed as each job ends, so a kill loses nothing
  already done; temporary files that a killed run left are removed when the next run starts. A
  completed run rewrites the table in input order.
* **Engines.** ``"local"``: with one worker the jobs run in this process; with more, in a pool
  of ``spawn``-ed processes, each loading the network once (``prepare_worker``) and giving it
  ``cores // workers`` threads. A worker that dies (out of memory, a crash in a library) fails
  only its own file: the jobs it may have held are re-run one at a time in a fresh process.
  ``"dask"``: the same jobs on a Dask distributed cluster (``batch_dask``).
"""

from __future__ import annotations

import csv
import multiprocessing
import os
import re
import signal
import threading
import time
from collections import deque
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import replace
from pathlib import Path

from .batch_job import (  # noqa: F401  (one job: defined there, part of this module's API)
    Job,
    failed_row,
    is_current,
    prepare_worker,
    run_job,
)
from .errors import AGNDCError
from .gridio import (
    GRID_EXTENSIONS,
    MESH_EXTENSIONS,
    MESH_SAVE_EXTENSIONS,
    TEMP_MARK,
    is_grid_path,
    is_mesh_path,
)
from .labelmaps import check_grid_method, parse_labels
from .options import RemeshOptions
from .pipeline import CHECKPOINT_NAMES, METHODS
from .runtime.parallel import default_threads

CSV_NAME = "batch.csv"
#: columns of batch.csv: label is the label value of a per-label output (else empty), grid the
#: remeshed grid's shape (X x Y x Z), seconds the job's (label's) wall time, peak_rss_mb the
#: peak resident memory of the process that ran it so far
CSV_FIELDS = ("input", "output", "label", "method", "grid", "faces", "vertices", "seconds",
              "status", "error", "peak_rss_mb", "worker")
OUTPUT_FORMATS = tuple(ext[1:] for ext in MESH_SAVE_EXTENSIONS)  # ply, obj, stl, glb
MANIFEST_EXTENSIONS = (".txt", ".lst", ".csv")
ENGINES = ("local", "dask")
#: jobs handed to a local pool per worker at a time: enough to keep every worker busy, few
#: enough that a dying worker leaves a short list of suspects
IN_FLIGHT_PER_WORKER = 2
_TEMP_NAME = re.compile(re.escape(TEMP_MARK) + r"\d+\.")


# --- inputs ---------------------------------------------------------------------------------


def discover_inputs(inputs, out_dir, *, fmt: str = "ply", recursive: bool = True) -> list[Job]:
    """Jobs for files, folders and manifests, in the given order (folders sorted).

    Raises AGNDCError (a usage error) for a missing path, an unsupported file, no input at all,
    or two inputs that would write the same output.
    """
    out_dir = Path(out_dir).absolute()
    jobs = []
    for item in inputs:
        jobs += _expand(Path(item), out_dir, fmt, recursive, listed=False)
    if not jobs:
        names = ", ".join(str(item) for item in inputs)
        raise AGNDCError(f"no mesh or grid files in {names or 'the inputs'}")
    return _unique(jobs)


def find_files(folder, *, recursive: bool = True, exclude=None) -> list[Path]:
    """Mesh and grid files in ``folder`` (sorted), without temporary files and ``exclude``'s
    subtree (the output folder, so outputs are never read back as inputs)."""
    folder, found = Path(folder), []
    skip = Path(exclude).resolve() if exclude is not None else None
    for root, dirs, files in os.walk(folder):
        dirs[:] = sorted(d for d in dirs if recursive and Path(root, d).resolve() != skip)
        found += [Path(root, name) for name in files
                  if (is_grid_path(name) or is_mesh_path(name)) and not _TEMP_NAME.search(name)]
    return sorted(found)


def read_manifest(path) -> list[tuple[Path, str | None]]:
    """(input path, output name or None) per manifest entry, inputs relative to its folder."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise AGNDCError(f"{path}: cannot read the manifest ({exc})") from None
    if path.suffix.lower() == ".csv":
        rows = [row for row in csv.reader(text.splitlines()) if row and row[0].strip()]
    else:
        rows = [[line.strip()] for line in text.splitlines()]
    header = [cell.strip().lower() for cell in rows[0]] if rows else []
    column = {"input": 0, "output": None}
    if "input" in header:
        column = {"input": header.index("input"),
                  "output": header.index("output") if "output" in header else None}
        rows = rows[1:]
    entries = []
    for row in rows:
        name = row[column["input"]].strip() if len(row) > column["input"] else ""
        if not name or name.startswith("#"):
            continue
        out = column["output"]
        output = (row[out].strip() or None) if out is not None and len(row) > out else None
        entries.append((path.parent / Path(name).expanduser(), output))
    return entries


def output_name(relative, fmt: str) -> Path:
    """``sub/x.nii.gz`` -> ``sub/x.<fmt>``: the input's relative path with the mesh extension."""
    relative = Path(relative)
    name = relative.name
    ext = max((e for e in GRID_EXTENSIONS + MESH_EXTENSIONS if name.lower().endswith(e)),
              key=len, default=relative.suffix)
    return relative.with_name(f"{name[:len(name) - len(ext)] or name}.{fmt}")


def _expand(path: Path, out_dir: Path, fmt: str, recursive: bool, listed: bool) -> list[Job]:
    """Jobs for one command-line item (``listed=False``) or one manifest entry (True)."""
    if path.is_dir():
        if path.resolve() == out_dir.resolve():
            raise AGNDCError(f"{path}: the output folder cannot also be an input folder")
        return [_job(p, out_dir / output_name(p.relative_to(path), fmt))
                for p in find_files(path, recursive=recursive, exclude=out_dir)]
    if path.suffix.lower() in MANIFEST_EXTENSIONS and not listed:
        if not path.is_file():
            raise AGNDCError(f"{path}: no such manifest")
        return [job for entry, output in read_manifest(path)
                for job in ([_job(entry, out_dir / output)] if output else
                            _expand(entry, out_dir, fmt, recursive, listed=True))]
    if not listed:  # a manifest's missing or odd entry is that file's failed row instead
        if not path.exists():
            raise AGNDCError(f"{path}: no such file or folder")
        if not (is_grid_path(path) or is_mesh_path(path)):
            raise AGNDCError(f"{path}: not a mesh ({', '.join(MESH_EXTENSIONS)}), a grid "
                             f"({', '.join(GRID_EXTENSIONS)}) or a manifest "
                             f"({', '.join(MANIFEST_EXTENSIONS)})")
    return [_job(path, out_dir / output_name(path.name, fmt))]


def _job(source: Path, output: Path) -> Job:
    return Job(os.path.abspath(source), os.path.abspath(output))


def _unique(jobs: list[Job]) -> list[Job]:
    """Drop repeated jobs; refuse an input that is its own output, or two inputs that map to one
    output."""
    by_output: dict[str, Job] = {}
    for job in jobs:
        if job.input == job.output:
            raise AGNDCError(f"{job.input}: its output would replace it; choose another output "
                             "folder or --format")
        other = by_output.setdefault(job.output, job)
        if other.input != job.input:
            raise AGNDCError(f"{other.input} and {job.input} would both be written to "
                             f"{job.output}; rename one or list them with an output column "
                             "in a CSV manifest")
    return list(by_output.values())


def is_done(job: Job) -> bool:
    """True when every output the job writes is known and up to date (``is_current``); a
    per-label job over every label is never done before it has read its file."""
    outputs = job.known_outputs()
    return outputs is not None and all(is_current(job.input, output) for output in outputs)


# --- engines --------------------------------------------------------------------------------


def run_serial(jobs, options: RemeshOptions, on_rows, func=run_job) -> None:
    """Every job in this process, one after another; ``on_rows(job, rows)`` as each ends."""
    for job in jobs:
        on_rows(job, func(job, options))


def run_pool(jobs, options: RemeshOptions, workers: int, on_rows, func=run_job) -> None:
    """Every job in a pool of ``workers`` processes; ``on_rows(job, rows)`` (in this process)
    gets each job's rows as it ends.

    At most ``IN_FLIGHT_PER_WORKER * workers`` jobs are handed out at a time. When a worker dies
    the pool breaks; the jobs that were handed out are then re-run one by one, each alone in a
    fresh process, so only the file that kills its worker gets a failed row. Ctrl-C terminates
    the workers (their temporary files are swept by ``remesh_many``) and propagates.
    """
    threads = options.threads or max(1, default_threads() // workers)
    todo, running = deque(jobs), {}
    pool = _new_pool(workers, options, threads)
    try:
        while todo or running:
            while todo and len(running) < IN_FLIGHT_PER_WORKER * workers:
                job = todo.popleft()
                running[pool.submit(func, job, options)] = job
            done, _ = wait(running, return_when=FIRST_COMPLETED)
            broken = False
            for future in done:
                job = running.pop(future)
                try:
                    on_rows(job, future.result())
                except BrokenProcessPool:
                    running[future] = job  # a suspect: re-run below
                    broken = True
                except Exception as exc:
                    on_rows(job, [failed_row(job, options, f"{type(exc).__name__}: {exc}")])
            if broken:
                pool.shutdown(wait=True)
                for job in list(running.values()):
                    on_rows(job, _run_alone(job, options, threads, func))
                running.clear()
                pool = _new_pool(workers, options, threads)
    except BaseException:
        _terminate(pool)
        raise
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def _new_pool(workers: int, options: RemeshOptions, threads: int) -> ProcessPoolExecutor:
    # spawn, not fork: a forked copy of a process that has started torch's thread pools can hang
    return ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn"),
                               initializer=_init_pool_worker,
                               initargs=(options, threads, os.getpid()))


def _run_alone(job: Job, options: RemeshOptions, threads: int, func) -> list[dict]:
    """A suspect job of a broken pool, alone in a fresh process: its rows, or a failed row if
    that process dies too."""
    pool = _new_pool(1, options, threads)
    try:
        return pool.submit(func, job, options).result()
    except BrokenProcessPool:
        return [failed_row(job, options, "the worker process died while remeshing this file "
                           "(out of memory? a crash in a library?)")]
    except BaseException:
        _terminate(pool)
        raise
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def _init_pool_worker(options: RemeshOptions, threads: int, parent_pid: int) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's to handle
    _exit_with_parent(parent_pid)
    try:
        prepare_worker(options, threads)
    except AGNDCError:
        # an initializer that raises breaks the whole pool; each job meets the same error
        # (an unreadable checkpoint, say) in remesh and reports it in its own row instead
        pass


def _exit_with_parent(parent_pid: int) -> None:
    """End this worker when the batch process is gone (killed: no one else would end it)."""

    def watch():
        while os.getppid() == parent_pid:
            time.sleep(0.5)
        os._exit(1)

    threading.Thread(target=watch, name="agndc-parent-watch", daemon=True).start()


def _terminate(pool: ProcessPoolExecutor) -> None:
    # Python 3.14 has terminate_workers(); before that the processes are only reachable here
    for process in list((getattr(pool, "_processes", None) or {}).values()):
        process.terminate()


def remove_temp_files(folder) -> int:
    """Delete the ``*.tmp-<pid>.*`` files a killed writer left under ``folder``; their count."""
    removed = 0
    for root, _, files in os.walk(folder):
        for name in files:
            if _TEMP_NAME.search(name):
                Path(root, name).unlink(missing_ok=True)
                removed += 1
    return removed


# --- the table and the public entry point ---------------------------------------------------


class CsvLog:
    """``batch.csv``, written one row at a time and flushed, so a kill loses no finished row."""

    def __init__(self, path, fields=CSV_FIELDS):
        self.path = Path(path)
        self._file = self.path.open("w", newline="", encoding="utf-8")
        self._writer = csv.DictWriter(self._file, fields, restval="", extrasaction="ignore")
        self._writer.writeheader()
        self._file.flush()

    def write(self, row: dict) -> None:
        self._writer.writerow(row)
        self._file.flush()

    def close(self) -> None:
        self._file.close()


def read_rows(path) -> list[dict]:
    """The rows of a batch.csv ([] when there is none or it cannot be read)."""
    try:
        with open(path, newline="", encoding="utf-8") as handle:
            return list(csv.DictReader(handle))
    except (OSError, csv.Error, UnicodeDecodeError):
        return []


def write_rows(path, rows, fields=CSV_FIELDS) -> None:
    """Write a whole table through a temporary name and an atomic rename."""
    path = Path(path)
    temp = path.with_name(f"{path.name}{TEMP_MARK}{os.getpid()}.csv")
    with temp.open("w", newline="", encoding="utf-8") as handle:
        writer = csv.DictWriter(handle, fields, restval="", extrasaction="ignore")
        writer.writeheader()
        writer.writerows(rows)
    os.replace(temp, path)


def remesh_many(inputs, out_dir, options: RemeshOptions | None = None, *, fmt: str = "ply",
                workers: int | None = None, engine: str = "local", scheduler: str | None = None,
                overwrite: bool = False, progress: bool = False, per_label: bool = False,
                labels=None, **changes) -> list[dict]:
    """Remesh every input (files, folders, manifests) into ``out_dir``; the rows of batch.csv.

    Args:
        inputs: paths of files, folders (recursive) and manifests; see the module docstring.
        out_dir: output folder (created); receives one ``<name>.<fmt>`` per input + batch.csv.
        per_label: read each input as a label map (.nii .nii.gz .npy .npz) and write one
            ``<name>_label-<value>.<fmt>`` per label (``labelmaps.label_output_path``).
        labels: only these labels (ints or a ``labelmaps.parse_labels`` string such as
            "1,3,7"; implies ``per_label``); a label missing from a file is that label's
            failed row.
        fmt: "ply", "obj", "stl" or "glb".
        options: the ``RemeshOptions`` of every file, with ``changes`` to its fields, as for
            ``pipeline.remesh_file`` / ``agndc remesh`` (``threads``: per job; None = the
            worker's share of the cores).
        workers: processes (local pool, or a Dask LocalCluster); None = the CPU cores.
        engine: "local" or "dask"; scheduler: a Dask scheduler address (None = a LocalCluster).
        overwrite: redo outputs that are already there and up to date.
        progress: show a tqdm bar (files/s, ETA) on stderr.

    Returns:
        One dict per output (per input; per label of each input with ``per_label``), in input
        order (then label order), with the CSV_FIELDS keys; status "ok", "failed" (error says
        why) or "skipped". Bad inputs never raise; bad arguments raise AGNDCError.
    """
    batch = RemeshOptions.of(options, **changes)
    if batch.checkpoint:  # absolute: workers may run in another folder or host
        batch = RemeshOptions.of(batch, checkpoint=os.path.abspath(batch.checkpoint))
    workers = default_threads() if workers is None else workers
    _check_arguments(batch, fmt, workers, engine, scheduler)
    wanted = _wanted_labels(batch, per_label, labels)
    out_dir = Path(out_dir)
    jobs = discover_inputs(inputs, out_dir, fmt=fmt)
    if wanted is not None:
        jobs = [replace(job, per_label=True, labels=wanted, overwrite=overwrite) for job in jobs]
    out_dir.mkdir(parents=True, exist_ok=True)
    remove_temp_files(out_dir)
    previous = {row.get("output"): row for row in read_rows(out_dir / CSV_NAME)}
    rows: dict[str, list[dict]] = {}  # job output -> the job's rows
    log = CsvLog(out_dir / CSV_NAME)
    todo = []
    for job in jobs:
        if overwrite or not is_done(job):
            todo.append(job)
        else:
            rows[job.output] = [_skipped_row(job.input, output, label, previous.get(output))
                                for output, label in zip(job.known_outputs(),
                                                         job.labels or [""])]
            for row in rows[job.output]:
                log.write(row)
    bar = _progress_bar(len(todo), len(jobs) - len(todo), enabled=progress)

    def on_rows(job: Job, job_rows: list[dict]) -> None:
        # an output the job found up to date keeps the previous run's numbers, as above
        rows[job.output] = [_skipped_row(row["input"], row["output"], row["label"],
                                         previous.get(row["output"]))
                            if row["status"] == "skipped" else row for row in job_rows]
        for row in rows[job.output]:
            log.write(row)
        bar.update(1)
        if any(row["status"] == "failed" for row in job_rows):
            bar.set_postfix(failed=sum(row["status"] == "failed"
                                       for job_rows in rows.values() for row in job_rows))

    try:
        if engine == "dask":
            from .batch_dask import run_dask  # batch_dask imports batch_job, not this module

            run_dask(todo, batch, workers, scheduler, on_rows)
        elif workers == 1 or len(todo) <= 1:
            run_serial(todo, batch, on_rows)
        else:
            run_pool(todo, batch, min(workers, len(todo)), on_rows)
    finally:
        bar.close()
        log.close()
        remove_temp_files(out_dir)
    ordered = [row for job in jobs for row in rows[job.output]]
    write_rows(out_dir / CSV_NAME, ordered)
    return ordered


def _wanted_labels(options: RemeshOptions, per_label: bool, labels) -> tuple[int, ...] | None:
    """The labels a per-label batch meshes (empty: every label of each file), checked before
    any work; None when the batch is not per label."""
    if isinstance(labels, str):
        labels = parse_labels(labels)
    if not (per_label or labels):
        return None
    check_grid_method(options.method)
    return tuple(dict.fromkeys(int(label) for label in labels or ()))


def _check_arguments(options: RemeshOptions, fmt, workers, engine, scheduler) -> None:
    if fmt not in OUTPUT_FORMATS:
        raise AGNDCError(f"output format {fmt!r}: choose one of {', '.join(OUTPUT_FORMATS)}")
    if options.method not in METHODS:
        raise AGNDCError(f"unknown method {options.method!r}; choose one of {', '.join(METHODS)}")
    if engine not in ENGINES:
        raise AGNDCError(f"unknown engine {engine!r}; choose one of {', '.join(ENGINES)}")
    if scheduler and engine != "dask":
        raise AGNDCError("a scheduler address needs the dask engine (--engine dask)")
    if workers < 1:
        raise AGNDCError(f"workers must be at least 1, got {workers}")
    if options.voxel_size is not None and not options.voxel_size > 0:
        raise AGNDCError(f"voxel size must be positive, got {options.voxel_size}")
    if options.low_poly:
        from .decimate import check_options

        check_options(options.decimate_error, options.target_faces)
    if options.method in CHECKPOINT_NAMES:  # fail before the workers start, not once per file
        from .checkpoint import default_checkpoint_path

        default = default_checkpoint_path(CHECKPOINT_NAMES[options.method])
        checkpoint = Path(options.checkpoint or default)
        if not checkpoint.is_file():
            raise AGNDCError(f"checkpoint not found: {checkpoint}")


def _skipped_row(source: str, output: str, label, previous: dict | None) -> dict:
    """The row of an output that is up to date: the previous run's numbers for it, if
    batch.csv had them."""
    row = dict(previous or {}, input=source, output=output, label=label, status="skipped",
               error="")
    return {key: row.get(key, "") for key in CSV_FIELDS}


def _progress_bar(total: int, skipped: int, *, enabled: bool):
    from tqdm import tqdm

    desc = f"agndc batch ({skipped} skipped)" if skipped else "agndc batch"
    return tqdm(total=total, desc=desc, unit="file", disable=not enabled, smoothing=0.1)


def summary(rows: list[dict]) -> dict:
    """Counts per status: {"ok": n, "failed": n, "skipped": n} (outputs: per label when the
    batch is per label)."""
    return {status: sum(row["status"] == status for row in rows)
            for status in ("ok", "failed", "skipped")}

