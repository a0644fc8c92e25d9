"""Progress of a long run: one fraction from 0 to 1 with a message, that keeps moving.

A run is a sequence of named stages (``Stages``). Each stage gets a span of [0, 1] in
proportion to its expected seconds (``pipeline.expected_stages``, from ``plan.stage_seconds``),
so the bar moves at about the same speed through every stage. Inside a stage the bar moves on
every cancellation check the stage makes (the long stages check between chunks of their work:
the voxeliser, Sharp's exact intersections, the normal filter, the Chamfer distance), at a share
of the span interpolated from the stage's elapsed and expected time (``interpolated_share``).
The network reports from inside itself the same way (``inference._Reporter``).
``benchmarks/bench_progress.py`` records every update of the Blender add-on's runs (docs/blender.md,
"Progress").
"""

from __future__ import annotations

import time

import numpy as np

from .errors import CancelledError

#: seconds between two progress reports from inside a stage (the Blender operator redraws its
#: bar every 0.1 s; the network's reporter uses the same interval)
PROGRESS_INTERVAL = 0.1
#: share of its span a stage reaches at its expected time when it runs long: below this the
#: share is the elapsed share of the expected time; above it the bar keeps creeping towards the
#: span's end instead of stopping (a stage that takes twice as long as expected is at 0.93)
LINEAR_SHARE = 0.8


def subrange(progress, lo: float, hi: float):
    """A progress callback that maps [0, 1] onto [lo, hi] of ``progress`` (None stays None)."""
    if progress is None:
        return None
    return lambda fraction, message: progress(_between(lo, hi, fraction), message)


def _between(lo: float, hi: float, share: float) -> float:
    """The point ``share`` of the way from lo to hi (exactly hi at share 1, so a run's last
    report is exactly 1)."""
    return lo * (1.0 - share) + hi * share


def interpolated_share(elapsed: float, expected: float) -> float:
    """Share of a stage's span to show ``elapsed`` seconds into a stage expected to take
    ``expected`` seconds: linear up to ``LINEAR_SHARE``, then approaching 1 without reaching
    it (hyperbolically: a stage that runs long still moves the bar, ever more slowly)."""
    if expected <= 0:
        return 0.0
    ratio = elapsed / expected
    if ratio <= LINEAR_SHARE:
        return ratio
    rest = 1.0 - LINEAR_SHARE
    # slope 1 where it meets the linear part, 1 - rest / 2 at ratio LINEAR_SHARE + rest
    return 1.0 - rest / (1.0 + (ratio - LINEAR_SHARE) / rest)


def raise_if_cancelled(cancel) -> None:
    """Raise CancelledError once ``cancel`` (an object with ``is_set()``, or None) is set."""
    if cancel is not None and cancel.is_set():
        raise CancelledError("remesh cancelled")


class Stages:
    """Times named stages, reports progress and honours cancellation between and inside them.

    Args:
        progress: callable(fraction, message) or None.
        cancel: object with ``is_set()`` or None.
        expected: {stage name: expected seconds} of the stages about to run, in order: each
            gets a span of [0, 1] in proportion to its seconds. A stage run without an entry
            gets no span (it reports where the previous stage ended).
        prefix: put before every message ("Part: ").
    """

    def __init__(self, progress, cancel, expected: dict | None = None, prefix: str = ""):
        self.progress, self.cancel, self.prefix = progress, cancel, prefix
        self.timings: dict[str, float] = {}
        self.expected = {name: max(float(seconds), 0.0)
                         for name, seconds in (expected or {}).items()}
        seconds = np.array(list(self.expected.values()), dtype=np.float64)
        if seconds.sum() <= 0:
            seconds[:] = 1.0
        bounds = np.concatenate([[0.0], np.cumsum(seconds) / seconds.sum()])
        bounds[-1] = 1.0  # exactly, whatever the rounding of the sum
        self.spans = {name: (float(lo), float(hi))
                      for name, lo, hi in zip(self.expected, bounds[:-1], bounds[1:])}
        self._start = time.perf_counter()
        self._stage = None  # (name, lo, hi, expected seconds, start time) of the running stage
        self._last = self._start
        self.reported = 0.0

    def span(self, name: str) -> tuple[float, float]:
        """[lo, hi] of a stage (where the last stage ended, twice, for one without a span)."""
        return self.spans.get(name, (self.reported, self.reported))

    def report(self, fraction: float, message: str) -> None:
        """Forward progress (never backwards) with the prefix."""
        if self.progress is None:
            return
        self.reported = max(self.reported, min(float(fraction), 1.0))
        self.progress(self.reported, self.prefix + message)
        self._last = time.perf_counter()

    def check(self) -> None:
        """Raise CancelledError once the run is cancelled; inside a stage, also report its
        progress (at most every ``PROGRESS_INTERVAL``). Long stages call this between chunks."""
        raise_if_cancelled(self.cancel)
        if self.progress is None or self._stage is None:
            return
        now = time.perf_counter()
        if now - self._last < PROGRESS_INTERVAL:
            return
        name, lo, hi, expected, start = self._stage
        self.report(_between(lo, hi, interpolated_share(now - start, expected)), name)

    def run(self, name: str, func, *args, **kwargs):
        """``func(*args, **kwargs)`` as the stage ``name``: checked, reported, timed."""
        self._stage = None
        self.check()
        lo, hi = self.span(name)
        self.report(lo, name)
        start = time.perf_counter()
        self._stage = (name, lo, hi, self.expected.get(name, 0.0), start)
        try:
            out = func(*args, **kwargs)
        finally:
            self._stage = None
        self.timings[name] = self.timings.get(name, 0.0) + time.perf_counter() - start
        return out

    def sub(self, name: str):
        """A progress callback for work that reports on its own (the network, a nested run),
        mapped onto the span of stage ``name`` and prefixed; None without ``progress``."""
        if self.progress is None:
            return None
        lo, hi = self.span(name)
        return subrange(self.report, lo, hi)

    @property
    def seconds(self) -> float:
        return time.perf_counter() - self._start


class ProgressLog:
    """A progress callback that records every update, and what a user watching it saw: the
    longest wait between two updates and the longest time one whole percentage was shown
    (``benchmarks/bench_progress.py`` and the tests read it).

    ``updates``: (seconds since the log was made, fraction, message) per call; ``finish()``
    ends the run (its end counts as a last update at 1).
    """

    def __init__(self):
        self.start = time.perf_counter()
        self.updates: list[tuple[float, float, str]] = []
        self.total = 0.0

    def __call__(self, fraction: float, message: str) -> None:
        self.updates.append((time.perf_counter() - self.start, float(fraction), message))

    def finish(self) -> float:
        """End the run; its seconds."""
        self.total = time.perf_counter() - self.start
        return self.total

    def _marks(self) -> list[tuple[float, float, str]]:
        return [(0.0, 0.0, "(start)"), *self.updates, (self.total, 1.0, "(end)")]

    def longest_gap(self) -> tuple[float, tuple, tuple]:
        """(seconds, update before, update after) of the longest wait between two updates
        (the start and the end of the run count as updates)."""
        marks = self._marks()
        gaps = np.diff([t for t, _, _ in marks])
        k = int(np.argmax(gaps))
        return float(gaps[k]), marks[k], marks[k + 1]

    def longest_flat(self) -> tuple[float, int, tuple]:
        """(seconds, percent, first update) of the longest stretch in which the bar showed one
        whole percentage (its messages may change within it)."""
        marks = self._marks()
        times = np.array([t for t, _, _ in marks])
        shown = np.array([int(100 * f) for _, f, _ in marks])
        starts = np.concatenate([[0], np.flatnonzero(np.diff(shown)) + 1])
        ends = np.concatenate([starts[1:], [len(marks) - 1]])
        lengths = times[ends] - times[starts]
        k = int(np.argmax(lengths))
        return float(lengths[k]), int(shown[starts[k]]), marks[starts[k]]

    def backwards(self) -> list[tuple]:
        """The updates whose fraction is lower than the one before (none, in a good run)."""
        return [b for a, b in zip(self.updates, self.updates[1:]) if b[1] < a[1]]
