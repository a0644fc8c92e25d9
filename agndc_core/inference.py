"""Fast inference: padded lattice -> per-point dual vertices and edge probabilities.

Two runtimes run the same checkpoint: the numpy one (``runtime/``, a ``runtime.Network``: the
CPU default of the CLI, the batch script and the Blender extension, no torch needed) and torch
(an ``nn.AGNDCCascade``: training, CUDA, and the reference the numpy one is tested against).
``predict_lattice`` takes either. Two paths over the same network:

* ``mode="band"`` (default): every scale is evaluated on the band of lattice points within
  ``config.band_radius`` of the surface (``nn/band_ops.py``); far points take the far-field
  value of their type. Exact for a model trained with band evaluation
  (``AGNDCCascade.forward_band``), an approximation for densely trained weights that improves
  with the radius (``band_radius=`` overrides it).
* ``mode="dense"``: the plain training forward on the whole lattice (reference; slow on CPU).

Large lattices are cut into tiles, **scale by scale**: the coarsest scale is predicted tile by
tile, assembled, and handed to the next finer scale, so each tile needs context (``TILE_HALO``
points at its own scale) for one network only, never for the whole cascade. Tile origins are
multiples of the windows and far-field periods, so a tile sees exactly the same lattice
positions as the whole lattice does; only information from beyond the halo is lost.

Progress and cancellation reach *inside* each tile: the numpy network calls the reporter
between layers and between chunks of rows; for torch, a thread-local ``TorchFunctionMode``
sees every torch call. Each call checks ``cancel`` and reports progress at most every
``PROGRESS_INTERVAL`` seconds, interpolated within the tile from its expected work (its share of
the surface, the band's size, weighted by its scale: ``_work``) and the speed measured on the
tiles before it (``progress.interpolated_share``). This module does not load torch.
"""

from __future__ import annotations

import math
import time

import numpy as np

from .errors import AGNDCError, CancelledError, GridError
from .grid import LATTICE_PAD, occupancy_pyramid, pad_to_lattice
from .progress import PROGRESS_INTERVAL, interpolated_share
from .runtime.band import sigmoid

#: band vs dense agreement (absolute, network output units) where the band covers the network's
#: receptive field: float32 rounding of a different summation order only
BAND_TOLERANCE = 1e-4
#: tiled vs untiled agreement (absolute) with a ``TILE_HALO`` halo (measured ~1e-5 on random
#: He-initialised networks of the default architecture; a 16-point halo gave ~1e-2)
TILE_TOLERANCE = 1e-3
#: context kept around each tile core, in lattice points of the tile's own scale
TILE_HALO = 24
#: lattices with more points than this are tiled when ``tile=None``
AUTO_TILE_LIMIT = 160 ** 3
#: tile core edge (lattice points) used when tiling automatically: ~2 GB peak at width 64
AUTO_TILE = 128
MODES = ("band", "dense")
#: Progress is reported every ``progress.PROGRESS_INTERVAL`` s from inside a tile.
#: Cancellation is checked on every torch call (15,368 calls in a 20 s 155³ run, at most 0.23 s
#: apart): ``benchmarks/bench_cancel.py`` measured a stop 0.01-0.06 s after cancel at 155³
#: (1 thread, 2-core CPU shared with a training job), progress every 0.11 s (median; longest gap
#: 0.28 s) and no measurable overhead.
#: Seconds per unit of ``_work`` at each scale relative to the finest: each coarser scale costs
#: about half as much per surface point (measured with the shipped AGNDC, 2 threads: scales 0, 1,
#: 2 took 118, 55 and 28 us per unit on a brain-sized mask, 79, 42 and 26 us on a CAD part at
#: 128³). With one cost for every scale, the finest scale's time would be predicted from the
#: coarser ones at about half its length, and the bar would wait at the end of its share.
SCALE_COST_RATIO = 0.5


def predict_lattice(model, lattice, *, mode: str = "band", tile: int | None = None,
                    progress=None, cancel=None, device=None, band_radius: int | None = None,
                    canonical: bool = True, edges: bool = True, high_margin: int = 0):
    """Run the AGNDC cascade on a padded dual-contouring lattice (grid.py convention).

    Args:
        model: an ``AGNDCCascade`` (put in eval mode; moved to ``device`` if given).
        lattice: (Dx, Dy, Dz) bool, True = inside; sides that are not multiples of
            2**levels are padded by repeating the last layer and cropped again.
        mode: "band" or "dense" (module docstring).
        tile: tile core edge in lattice points (rounded up to the alignment); None = automatic
            (tiles of ``AUTO_TILE`` above ``AUTO_TILE_LIMIT`` points); 0 = never tile.
        progress: callable(fraction: float, message: str), called between tiles and at most
            every ``PROGRESS_INTERVAL`` s inside one; cancel: object with ``is_set()``, checked
            on every torch call while the network runs (raises ``CancelledError``).
        device: torch device ("cpu", "cuda"); default: where the model is.
        band_radius: overrides ``model.config.band_radius`` (band mode).
        canonical: run the network on ``trained_window`` of the lattice (the shape with the
            empty margins voxelising gives), so the result does not depend on how much empty
            space surrounds the shape; False runs it on the lattice as given (diagnostics).
        edges: also return the finest edge probabilities; False (what contouring a binary grid
            needs: its edges come from the grid) returns None for them and, in the numpy
            runtime, keeps only the vertex channels of the finest scale (half its memory).
        high_margin: empty points added after the high end of each axis whose last layer is
            empty, the prediction cropped back (``methods.Method.high_margin``: where the
            network learned to put a face next to the high border); 0 runs the network on the
            lattice's own extent.

    Returns:
        vertex: (Dx, Dy, Dz, 3) float32 in [0, 1], the dual vertex of the cell at each point as
        an offset from its min corner; edge_prob: (Dx, Dy, Dz, 3) float32, probability that the
        edge leaving the point along +x, +y, +z is crossed.
    """
    if mode not in MODES:
        raise AGNDCError(f"unknown inference mode {mode!r}; choose one of {', '.join(MODES)}")
    lattice = _as_lattice(lattice)
    window = trained_window(lattice) if canonical else None
    if window is not None:
        return _predict_window(model, lattice, window, mode=mode, tile=tile, progress=progress,
                               cancel=cancel, device=device, band_radius=band_radius,
                               edges=edges, high_margin=high_margin)
    numpy_net = getattr(model, "backend", None) == "numpy"
    if numpy_net and (mode == "dense" or device not in (None, "cpu")):
        raise AGNDCError("the numpy runtime evaluates the band on the CPU only; load the "
                         "checkpoint with torch (checkpoint.load_checkpoint) for mode='dense' "
                         "or a CUDA device")
    if not numpy_net:
        if device is not None:
            model.to(device)
        model.eval()
    step = 2 ** model.levels
    shape = lattice.shape
    # an empty last layer repeated is the empty margin; an occupied one is repeated as before
    # (outside the lattice is then not known to be empty)
    margin = [0 if np.take(lattice, -1, axis).any() else high_margin for axis in range(3)]
    padded = np.pad(lattice, [(0, m + -(n + m) % step) for n, m in zip(shape, margin)],
                    mode="edge")
    report = _Reporter(progress, cancel)
    if mode == "dense":
        pred = _predict_dense(model, padded, report)
    else:
        if tile is None:
            tile = AUTO_TILE if padded.size > AUTO_TILE_LIMIT else 0
        channels = 3 if numpy_net and not edges else 6
        with _running(model, report):
            pred = _predict_band(model, padded, band_radius, int(tile), report, channels)
        report.segment(0.95, 0.95, "network output")
    pred = _to_numpy(pred)[:shape[0], :shape[1], :shape[2]]
    vertex = np.ascontiguousarray(pred[..., :3])
    np.clip(vertex, 0.0, 1.0, out=vertex)
    edge_prob = sigmoid(pred[..., 3:]) if edges else None
    report(1.0, "network done")
    return vertex, edge_prob


def _running(model, report):
    """The context a band evaluation runs in: the reporter reached from inside the network."""
    if getattr(model, "backend", None) == "numpy":
        return model.running(report.tick)
    from .nn.torch_inference import running

    return running(report)


def _predict_dense(model, padded, report):
    from .nn.torch_inference import predict_dense

    return predict_dense(model, padded, report)


def _to_numpy(pred) -> np.ndarray:
    if isinstance(pred, np.ndarray):
        return pred.astype(np.float32, copy=False)
    return pred.float().cpu().numpy()


def trained_window(lattice: np.ndarray):
    """Where the network should see this lattice: (start, window) or None if it already does.

    Training samples are voxelised meshes, so every shape starts exactly
    ``1 + grid.LATTICE_PAD`` points from the lattice's low end (``voxelize`` keeps one empty
    voxel, ``pad_to_lattice`` adds one layer), and the network learned its low-end border there:
    one more empty layer in front moves a box face by 0.25 voxel
    (docs/experiments/flat-face-bias.md). User grids
    (binvox, .vox, arrays) come with any margin, so the occupied box is re-framed exactly as
    ``pad_to_lattice`` frames a tight voxelisation. Only empty points are added or dropped.

    Returns:
        None when the lattice is already framed so, is empty, or has occupied border points
        (outside it is then not known to be empty); else (start (3,) int: lattice point of the
        window's point 0, possibly negative; window: the re-framed (X', Y', Z') bool lattice).
    """
    on_border = any(np.take(lattice, [0, -1], axis=axis).any() for axis in range(3))
    if on_border or not lattice.any():
        return None
    occupied = np.argwhere(lattice)
    lo, hi = occupied.min(0), occupied.max(0)
    core = lattice[lo[0]:hi[0] + 1, lo[1]:hi[1] + 1, lo[2]:hi[2] + 1]
    # the empty voxel voxelize keeps on every side, then the lattice padding of the training data
    # (training/data.py frames every sample so, whatever the model's levels)
    window = pad_to_lattice(np.pad(core, 1))
    start = lo - 1 - LATTICE_PAD
    if (start == 0).all() and window.shape == lattice.shape:
        return None
    return start, window


def _predict_window(model, lattice, window, **options):
    """``predict_lattice`` on the re-framed window, written back into the lattice's points."""
    start, sub = window
    vertex_sub, edge_sub = predict_lattice(model, sub, canonical=False, **options)
    # points outside the window have no crossed edge nearby: their values are never used
    dst = tuple(slice(max(a, 0), min(a + n, m)) for a, n, m in zip(start, sub.shape, lattice.shape))
    src = tuple(slice(d.start - a, d.stop - a) for d, a in zip(dst, start))
    vertex = np.full(lattice.shape + (3,), 0.5, dtype=vertex_sub.dtype)
    vertex[dst] = vertex_sub[src]
    edge_prob = None
    if edge_sub is not None:
        edge_prob = np.zeros(lattice.shape + (3,), dtype=edge_sub.dtype)
        edge_prob[dst] = edge_sub[src]
    return vertex, edge_prob


def _predict_band(model, lattice: np.ndarray, radius, tile: int, report, channels: int = 6):
    """(X, Y, Z, channels) scale-0 prediction by band evaluation, tiled scale by scale (the
    coarser scales keep all 6 channels: the next scale reads their edge logits)."""
    levels, cfg = model.levels, model.config
    grids = occupancy_pyramid(lattice, levels)
    periods = model.torus_periods
    plans, weights = [], []
    for s in range(levels + 1):
        align = math.lcm(cfg.window, periods[s], 2 if s < levels else 1)
        plans.append(list(_tiles(grids[s].shape, tile, align)))
        surface = _surface_points(grids[s])
        weights.append([_work(surface, region, s) for _, region in plans[s]])
    total = sum(map(sum, weights))
    done, coarser = 0.0, None
    for s in reversed(range(levels + 1)):
        grid = grids[s]
        out, torus = None, None
        for i, (core, region) in enumerate(plans[s]):
            report.segment(0.95 * done / total, 0.95 * (done + weights[s][i]) / total,
                           f"network scale {s}, tile {i + 1}/{len(plans[s])}", weights[s][i])
            sub = None
            if coarser is not None:
                half = tuple(slice(r.start // 2, r.stop // 2) for r in region)
                sub = (coarser[0][half], coarser[1])
            rows, ops = model.band_scale(s, grid[region], sub, radius,
                                         out_radius=1 if s == 0 else None)
            kept = channels if s == 0 else 6
            dense = ops.to_dense(rows[:, :kept])
            if out is None:
                out = (np.empty((*grid.shape, kept), dtype=np.float32)
                       if isinstance(dense, np.ndarray) else dense.new_empty(*grid.shape, kept))
            local = tuple(slice(c.start - r.start, c.stop - r.start) for c, r in zip(core, region))
            out[core] = dense[local]
            torus = rows[:ops.torus]
            done += weights[s][i]
        coarser = (out, torus)
    return model.add_prior(coarser[0], lattice)


def _tiles(shape, tile: int, align: int):
    """Yield (core, region) slice triples: cores partition the lattice, regions add the halo.

    About ``tile`` points per core edge; core and region bounds are multiples of ``align``
    (or the lattice end), so tiles see the lattice's windows and far-field phases.
    """
    if tile <= 0 or all(n <= tile for n in shape):
        whole = tuple(slice(0, n) for n in shape)
        yield whole, whole
        return
    halo = -(-TILE_HALO // align) * align
    bounds = []
    for n in shape:
        count = max(1, round(n / tile))  # a small remainder widens the last tile instead
        core = -(-n // (count * align)) * align
        edges = [min(i * core, n) for i in range(count)] + [n]
        bounds.append([(a, b) for a, b in zip(edges[:-1], edges[1:]) if b > a])
    for bx in bounds[0]:
        for by in bounds[1]:
            for bz in bounds[2]:
                cores = tuple(slice(a, b) for a, b in (bx, by, bz))
                regions = tuple(slice(max(0, a - halo), min(n, b + halo))
                                for (a, b), n in zip((bx, by, bz), shape))
                yield cores, regions


def _volume(region) -> int:
    return math.prod(r.stop - r.start for r in region)


def _surface_points(grid: np.ndarray) -> np.ndarray:
    """(X, Y, Z) bool: points with a 6-neighbour of the other value (where the band lies)."""
    surface = np.zeros(grid.shape, dtype=bool)
    for axis in range(3):
        lo = [slice(None)] * 3
        hi = [slice(None)] * 3
        lo[axis], hi[axis] = slice(None, -1), slice(1, None)
        # (X-1, Y, Z) etc.: the edge between two points along ``axis`` is crossed
        crossed = grid[tuple(lo)] != grid[tuple(hi)]
        surface[tuple(lo)] |= crossed
        surface[tuple(hi)] |= crossed
    return surface


def _work(surface: np.ndarray, region, scale: int = 0) -> float:
    """Relative cost of one tile of a scale: its surface points (the band) plus a little per
    point for the dense steps, times ``SCALE_COST_RATIO`` per scale above the finest."""
    return (float(surface[region].sum()) + _volume(region) / 100.0) * SCALE_COST_RATIO ** scale


class _Reporter:
    """Forwards progress and raises CancelledError when ``cancel`` is set.

    ``segment`` starts a piece of work that spans [lo, hi] of the whole; ``tick`` (called on every
    call from inside the network) checks cancellation and, every ``PROGRESS_INTERVAL`` s, reports a
    fraction interpolated within the segment from its elapsed time and expected duration (its
    ``work`` times the seconds per unit of work measured on the segments before it).
    """

    def __init__(self, progress, cancel):
        self.progress, self.cancel = progress, cancel
        self.active = progress is not None or cancel is not None
        self.lo = self.hi = 0.0
        self.message, self.work = "", 0.0
        self.start = self.last = time.perf_counter()
        self.seconds_done = self.work_done = 0.0
        self.reported = 0.0

    def __call__(self, fraction: float, message: str) -> None:
        self.check()
        if self.progress is not None:
            self.reported = max(self.reported, float(fraction))
            self.progress(self.reported, message)
            self.last = time.perf_counter()

    def check(self) -> None:
        if self.cancel is not None and self.cancel.is_set():
            raise CancelledError("inference cancelled")

    def segment(self, lo: float, hi: float, message: str, work: float = 0.0) -> None:
        now = time.perf_counter()
        if self.work > 0:  # the segment that ends now calibrates the speed
            self.seconds_done += now - self.start
            self.work_done += self.work
        self.lo, self.hi, self.message, self.work, self.start = lo, hi, message, work, now
        self(lo, message)

    def tick(self) -> None:
        self.check()
        now = time.perf_counter()
        if self.progress is None or now - self.last < PROGRESS_INTERVAL:
            return
        share = 0.0
        if self.work_done > 0 and self.work > 0:
            expected = self.seconds_done / self.work_done * self.work
            share = interpolated_share(now - self.start, expected)
        self(self.lo + (self.hi - self.lo) * share, self.message)


def _as_lattice(lattice) -> np.ndarray:
    array = np.asarray(lattice)
    if array.ndim != 3 or min(array.shape) < 1:
        raise GridError(f"a lattice must be a non-empty 3-D array, got shape {array.shape}")
    if array.dtype != bool:
        if array.dtype.kind not in "uif" or not np.isin(np.unique(array), (0, 1)).all():
            raise GridError("a lattice must be boolean (or 0/1), got values other than 0 and 1")
        array = array != 0
    return np.ascontiguousarray(array)
