"""Training crops: a window of one sample at one scale, with its coarser inputs, augmented.

A crop of scale s is ``size`` lattice points on a side at scale s, starting at ``origin`` (scale-s
points). It carries the input occupancy G_t of every scale t >= s (the coarser networks run on
it to produce P_{s+1}) and the labels of scale s. Origins are multiples of
``window * 2**(levels - s)`` so that every coarser crop starts on a whole coarse point and on a
window boundary, exactly as in the full lattice.

Augmentation is exact: an axis permutation and flips. Flipping maps lattice point p of the crop
to size-1-p but *cell* p (points p..p+1) to size-2-p, so cell-like arrays (vertex, surface, and
the edge channel along the flipped axis) are taken with one extra layer in front and shifted
after the flip; ``tests/core/test_training.py`` checks this against ``data.flip_permute`` on a
whole sample.
"""

from __future__ import annotations

import numpy as np

from ..grid import pool_occupancy


def take(array: np.ndarray, origin, size) -> np.ndarray:
    """``array[o:o+n]`` on the first three axes, zero-filled where it leaves the array."""
    out = np.zeros(tuple(size) + array.shape[3:], dtype=array.dtype)
    src, dst = [], []
    for o, n, d in zip(origin, size, array.shape[:3]):
        lo, hi = max(o, 0), min(o + n, d)
        if hi <= lo:
            return out
        src.append(slice(lo, hi))
        dst.append(slice(lo - o, hi - o))
    out[tuple(dst)] = array[tuple(src)]
    return out


def _point_crop(array, origin, size, flips):
    region = take(array, origin, size)
    for axis in np.nonzero(flips)[0]:
        region = np.flip(region, axis)
    return region


def _cell_crop(array, origin, size, flips, cell_axes=(0, 1, 2)):
    """Crop an array that is cell-like along ``cell_axes`` (point-like along the others)."""
    ext_origin = [o - 1 if a in cell_axes else o for a, o in enumerate(origin)]
    ext_size = [n + 1 if a in cell_axes else n for a, n in enumerate(size)]
    region = take(array, ext_origin, ext_size)
    for axis in np.nonzero(flips)[0]:
        region = np.flip(region, axis)
    # not flipped: drop the extra leading layer; flipped: flip, then drop (module docstring)
    keep = tuple(slice(1, None) if axis in cell_axes else slice(None) for axis in range(3))
    return region[keep]


def sample_pyramid(lattice: np.ndarray, levels: int) -> list[np.ndarray]:
    """Input occupancy G_0..G_levels of a padded scale-0 lattice (OR pooling, as at inference)."""
    grids = [np.asarray(lattice, dtype=bool)]
    for _ in range(levels):
        grids.append(pool_occupancy(grids[-1]))
    return grids


def make_crop(sample: dict, grids: list[np.ndarray], s: int, size: int, origin,
              perm, flips) -> dict:
    """One augmented crop of scale ``s``.

    Args:
        sample: arrays of ``data.load_sample`` (labels ``vertex{s}``, ``edge{s}``, ``surface{s}``).
        grids: ``sample_pyramid`` of the sample's lattice.
        s: trained scale; size: crop edge at scale s; origin: (3,) crop start at scale s.
        perm: axis permutation (3,); flips: (3,) bool, applied after the permutation.

    Returns:
        {"g": [G_s, G_{s+1}, ...] (size/2^k)^3 bool, "vertex": (n,n,n,3) float32,
         "edge": (n,n,n,3) bool, "surface": (n,n,n) bool}
    """
    perm = [int(a) for a in perm]
    flips = np.asarray(flips, dtype=bool)
    # crop in the permuted frame == permute the crop taken at the un-permuted origin
    inv_flips = np.empty(3, dtype=bool)
    inv_flips[perm] = flips  # flips[i] applies to new axis i == old axis perm[i]
    g = []
    for t in range(s, len(grids)):
        k = 2 ** (t - s)
        crop = _point_crop(grids[t], [o // k for o in origin], [size // k] * 3, inv_flips)
        g.append(np.ascontiguousarray(crop.transpose(perm)))
    n3 = [size] * 3
    surface = _cell_crop(sample[f"surface{s}"], origin, n3, inv_flips)
    vertex = _cell_crop(sample[f"vertex{s}"], origin, n3, inv_flips).astype(np.float32)
    for axis in np.nonzero(inv_flips)[0]:
        vertex[..., axis] = np.where(surface, 1.0 - vertex[..., axis], 0.0)
    edges = [_cell_crop(sample[f"edge{s}"][..., a], origin, n3, inv_flips, cell_axes=(a,))
             for a in range(3)]
    edge = np.stack(edges, axis=-1)
    return {
        "g": g,
        "surface": np.ascontiguousarray(surface.transpose(perm)),
        "vertex": np.ascontiguousarray(vertex.transpose(*perm, 3)[..., perm]),
        "edge": np.ascontiguousarray(edge.transpose(*perm, 3)[..., perm]),
    }


def random_crop_origin(surface: np.ndarray, size: int, align: int, rng) -> list[int]:
    """An aligned origin whose crop contains a random surface cell (anywhere inside it)."""
    cells = np.argwhere(surface)
    if len(cells) == 0:
        return [0, 0, 0]
    centre = cells[rng.integers(len(cells))]
    origin = []
    for c, d in zip(centre, surface.shape):
        # aligned starts that keep the cell at least one point inside the crop
        first = -(-(int(c) - size + 2) // align) * align
        starts = np.arange(max(first, 0), int(c), align)
        lo = int(rng.choice(starts)) if len(starts) else (int(c) // align) * align
        origin.append(min(lo, max(d - size, 0) // align * align))
    return origin
