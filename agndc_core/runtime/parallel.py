"""Threads for the numpy runtime: chunks of band rows on a small thread pool.

numpy's gathers and element-wise loops run on one core, and BLAS's own threads do not help the
small matmuls of one chunk (measured on 2 cores: a 16 -> 16 band convolution of 93k rows takes
22 ms serially with 2 BLAS threads, 14 ms on 2 Python threads with 1 BLAS thread each; numpy
releases the GIL inside ``take`` and ``matmul``). So the runtime splits its row loops over
``threads`` workers and, while a network runs, limits BLAS to one thread per worker
(``threadpoolctl``), which also keeps BLAS from spinning against the other programs of a busy
machine.
"""

from __future__ import annotations

import os
import threading
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager

import numpy as np

_state = {"threads": 1, "pool": None}
_local = threading.local()


def default_threads() -> int:
    """Cores this process may use (its affinity where the OS reports one)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # macOS, Windows
        return max(1, os.cpu_count() or 1)


def set_threads(n: int | None) -> int:
    """Use ``n`` worker threads (None or 0: ``default_threads()``); returns the count."""
    n = default_threads() if not n else max(1, int(n))
    if n != _state["threads"]:
        if _state["pool"] is not None:
            _state["pool"].shutdown(wait=True)
        _state["pool"] = ThreadPoolExecutor(n, thread_name_prefix="agndc") if n > 1 else None
        _state["threads"] = n
    return n


def get_threads() -> int:
    return _state["threads"]


def for_chunks(n: int, chunk: int, work, tick=None) -> None:
    """Call ``work(a, b)`` for consecutive row ranges [a, b) of at most ``chunk`` rows covering
    [0, n), on the worker threads; ``tick`` runs on the calling thread between results (progress
    and cancellation: an exception it raises stops the loop once the running chunks end)."""
    starts = range(0, n, chunk)
    pool = _state["pool"]
    if pool is None or len(starts) < 2:
        for a in starts:
            work(a, min(a + chunk, n))
            if tick is not None:
                tick()
        return
    futures = [pool.submit(work, a, min(a + chunk, n)) for a in starts]
    try:
        for future in futures:
            future.result()
            if tick is not None:
                tick()
    finally:
        for future in futures:
            future.cancel()


def scratch(name: str, shape, dtype=np.float32) -> np.ndarray:
    """A per-thread reusable buffer of at least ``shape`` (fresh large arrays page-fault)."""
    size = int(np.prod(shape))
    buffers = getattr(_local, "buffers", None)
    if buffers is None:
        buffers = _local.buffers = {}
    buf = buffers.get((name, np.dtype(dtype)))
    if buf is None or buf.size < size:
        buf = buffers[(name, np.dtype(dtype))] = np.empty(size, dtype=dtype)
    return buf[:size].reshape(shape)


@contextmanager
def blas_single_thread():
    """One BLAS thread per worker while a network runs (no-op without ``threadpoolctl``)."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        yield
        return
    with threadpool_limits(limits=1, user_api="blas"):
        yield
