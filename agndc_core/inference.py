"""Fast inference: padded lattice -> per-point dual vertices and edge probabilities.

Two paths over the same network:

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
"""

from __future__ import annotations

import math

import numpy as np
import torch

from .errors import AGNDCError, CancelledError, GridError
from .grid import occupancy_pyramid

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


def predict_lattice(model, lattice, *, mode: str = "band", tile: int | None = None,
                    progress=None, cancel=None, device=None, band_radius: int | None = None):
    """Run the AGNDC cascade on a padded dual-contouring lattice (grid.py convention).

    Args:
        model: an ``AGNDCCascade`` (put in eval mode; moved to ``device`` if given).
        lattice: (Dx, Dy, Dz) bool, True = inside; sides that are not multiples of
            2**levels are padded by repeating the last layer and cropped again.
        mode: "band" or "dense" (module docstring).
        tile: tile core edge in lattice points (rounded up to the alignment); None = automatic
            (tiles of ``AUTO_TILE`` above ``AUTO_TILE_LIMIT`` points); 0 = never tile.
        progress: callable(fraction: float, message: str); cancel: object with ``is_set()``,
            checked between tiles and scales (raises ``CancelledError``).
        device: torch device ("cpu", "cuda"); default: where the model is.
        band_radius: overrides ``model.config.band_radius`` (band mode).

    Returns:
        vertex: (Dx, Dy, Dz, 3) float32 in [0, 1], the dual vertex of the cell at each point as
        an offset from its min corner; edge_prob: (Dx, Dy, Dz, 3) float32, probability that the
        edge leaving the point along +x, +y, +z is crossed.
    """
    if mode not in MODES:
        raise AGNDCError(f"unknown inference mode {mode!r}; choose one of {', '.join(MODES)}")
    lattice = _as_lattice(lattice)
    if device is not None:
        model.to(device)
    model.eval()
    step = 2 ** model.levels
    shape = lattice.shape
    padded = np.pad(lattice, [(0, -n % step) for n in shape], mode="edge")
    report = _Reporter(progress, cancel)
    with torch.inference_mode():
        if mode == "dense":
            report(0.0, "AGNDC dense")
            g = torch.from_numpy(padded)[None].to(next(model.parameters()).device)
            pred = model(g)[0][0].permute(1, 2, 3, 0)
        else:
            if tile is None:
                tile = AUTO_TILE if padded.size > AUTO_TILE_LIMIT else 0
            pred = _predict_band(model, padded, band_radius, int(tile), report)
        pred = pred[:shape[0], :shape[1], :shape[2]].float()
        vertex = pred[..., :3].clamp(0.0, 1.0).cpu().numpy()
        edge_prob = torch.sigmoid(pred[..., 3:]).cpu().numpy()
    report(1.0, "AGNDC done")
    return np.ascontiguousarray(vertex), np.ascontiguousarray(edge_prob)


def _predict_band(model, lattice: np.ndarray, radius, tile: int, report) -> torch.Tensor:
    """(X, Y, Z, 6) scale-0 prediction by band evaluation, tiled scale by scale."""
    levels, cfg = model.levels, model.config
    grids = occupancy_pyramid(lattice, levels)
    periods = model.torus_periods
    plans = []
    for s in range(levels + 1):
        align = math.lcm(cfg.window, periods[s], 2 if s < levels else 1)
        plans.append(list(_tiles(grids[s].shape, tile, align)))
    total = sum(_volume(region) for plan in plans for _, region in plan)
    done, coarser = 0, None
    for s in reversed(range(levels + 1)):
        grid = grids[s]
        out, torus = None, None
        for i, (core, region) in enumerate(plans[s]):
            report(0.95 * done / total, f"AGNDC scale {s}, tile {i + 1}/{len(plans[s])}")
            sub = None
            if coarser is not None:
                half = tuple(slice(r.start // 2, r.stop // 2) for r in region)
                sub = (coarser[0][half], coarser[1])
            rows, ops = model.band_scale(s, grid[region], sub, radius,
                                         out_radius=1 if s == 0 else None)
            dense = ops.to_dense(rows)
            if out is None:
                out = dense.new_empty(*grid.shape, 6)
            local = tuple(slice(c.start - r.start, c.stop - r.start) for c, r in zip(core, region))
            out[core] = dense[local]
            torus = rows[:ops.torus]
            done += _volume(region)
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


class _Reporter:
    """Forwards progress and raises CancelledError when ``cancel`` is set."""

    def __init__(self, progress, cancel):
        self.progress, self.cancel = progress, cancel

    def __call__(self, fraction: float, message: str) -> None:
        if self.cancel is not None and self.cancel.is_set():
            raise CancelledError("AGNDC inference cancelled")
        if self.progress is not None:
            self.progress(float(fraction), message)


def _as_lattice(lattice) -> np.ndarray:
    array = np.asarray(lattice)
    if array.ndim != 3 or min(array.shape) < 1:
        raise GridError(f"a lattice must be a non-empty 3-D array, got shape {array.shape}")
    if array.dtype != bool:
        if array.dtype.kind not in "uif" or not np.isin(np.unique(array), (0, 1)).all():
            raise GridError("a lattice must be boolean (or 0/1), got values other than 0 and 1")
        array = array != 0
    return np.ascontiguousarray(array)
