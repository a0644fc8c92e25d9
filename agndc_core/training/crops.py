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

from ..grid import occupancy_pyramid


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


def transform_quadric(quadric: np.ndarray, perm, flips) -> np.ndarray:
    """(..., 6) quadrics (labels.QUADRIC_ENTRIES order) under flips of the given axes, then the
    axis permutation: Q' = P S Q S P^T with S = diag(+-1)."""
    from ..labels import QUADRIC_ENTRIES

    full = np.zeros(quadric.shape[:-1] + (3, 3), np.float32)
    for k, (r, c) in enumerate(QUADRIC_ENTRIES):
        full[..., r, c] = full[..., c, r] = quadric[..., k]
    sign = np.where(np.asarray(flips, bool), -1.0, 1.0).astype(np.float32)
    full *= sign[:, None] * sign[None, :]
    full = full[..., perm, :][..., :, perm]
    return np.stack([full[..., r, c] for r, c in QUADRIC_ENTRIES], axis=-1)


def make_crop(sample: dict, grids: list[np.ndarray], s: int, size: int, origin,
              perm, flips) -> dict:
    """One augmented crop of scale ``s``.

    Args:
        sample: arrays of ``data.load_sample`` (labels ``vertex{s}``, ``edge{s}``, ``surface{s}``).
        grids: ``grid.occupancy_pyramid`` of the sample's lattice.
        s: trained scale; size: crop edge at scale s; origin: (3,) crop start at scale s.
        perm: axis permutation (3,); flips: (3,) bool, applied after the permutation.

    Returns:
        {"g": [G_s, G_{s+1}, ...] (size/2^k)^3 bool, "vertex": (n,n,n,3) float32,
         "edge": (n,n,n,3) bool, "surface": (n,n,n) bool, and "quadric": (n,n,n,6) float32
         when the sample has ``quadric{s}``}
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
    extra = {}
    if f"quadric{s}" in sample:
        quadric = _cell_crop(sample[f"quadric{s}"], origin, n3, inv_flips)
        extra["quadric"] = np.ascontiguousarray(
            transform_quadric(quadric.transpose(*perm, 3), perm, inv_flips))
    return {
        **extra,
        "g": g,
        "surface": np.ascontiguousarray(surface.transpose(perm)),
        "vertex": np.ascontiguousarray(vertex.transpose(*perm, 3)[..., perm]),
        "edge": np.ascontiguousarray(edge.transpose(*perm, 3)[..., perm]),
    }


def random_crop_origin(surface, size: int, align: int, rng, margin: int = 0,
                       dims=None, outside: bool = False) -> list[int]:
    """An aligned origin whose crop holds a random surface cell ``margin`` cells from its border.

    Args:
        surface: (D) bool surface cells, or (n, 3) int coordinates of the surface cells.
        size: crop edge; align: origins are multiples of this; margin: context wanted around
            the chosen cell (it lands in ``margin .. size - 2 - margin`` where alignment allows).
        dims: the lattice shape when ``surface`` is given as coordinates (keeps crops inside).
        outside: let the crop reach past the lattice's ends (zero-filled by ``take``). Every
            sample's part starts 2 points from its lattice's low end, so crops kept inside the
            lattice show the network a crop border exactly that far from the low faces; with
            ``outside`` the empty space in front of a face varies by whole alignment steps.
    """
    cells = np.argwhere(surface) if surface.ndim == 3 else np.asarray(surface)
    dims = surface.shape if surface.ndim == 3 else dims
    if len(cells) == 0:
        return [0, 0, 0]
    centre = cells[rng.integers(len(cells))]
    origin = []
    for axis, c in enumerate(int(x) for x in centre):
        # aligned starts that keep the cell inside the crop, with margin where possible
        first = -(-(c - size + 2 + margin) // align) * align
        starts = np.arange(first if outside else max(first, 0), c - margin + 1, align)
        lo = int(rng.choice(starts)) if len(starts) else (c // align) * align
        if dims is not None and not outside:
            lo = min(lo, max(dims[axis] - size, 0) // align * align)
        origin.append(lo)
    return origin


def valid_cells(origin, size: int, dims, margin: int, perm, flips) -> np.ndarray:
    """(size, size, size) bool: cells of an augmented crop whose context is real data.

    A crop's border is replicate-padded by the network, which invents context; cells within
    ``margin`` of a border that lies *inside* the lattice are therefore not scored. Borders at or
    beyond the lattice's ends are real (empty space outside the padded lattice). ``perm`` and
    ``flips`` are ``make_crop``'s (flips in the permuted frame).
    """
    cell = np.arange(size)
    masks = []
    for new_axis in range(3):
        old = int(perm[new_axis])
        low_real = origin[old] <= 0
        high_real = origin[old] + size >= dims[old]
        if flips[new_axis]:  # cell p -> size - 2 - p swaps the two ends
            low_real, high_real = high_real, low_real
        ok = (low_real | (cell >= margin)) & (high_real | (cell <= size - 2 - margin))
        masks.append(ok)
    return masks[0][:, None, None] & masks[1][None, :, None] & masks[2][None, None, :]


class SparseSample:
    """A training sample held sparsely: packed input bits and labels of surface cells only.

    Dense labels of a 112x128x88 lattice (3 scales, with quadrics) take 56.3 MiB, this 3.8 MiB:
    a few percent of cells are surface cells, so thousands of samples fit in memory.
    ``window`` rebuilds dense arrays of any box on demand, zero-filled outside the lattice.
    """

    def __init__(self, sample: dict, levels: int):
        lattice = np.asarray(sample["lattice"], dtype=bool)
        self.recipe = sample.get("recipe")
        self.levels = levels
        self.shape0 = lattice.shape
        self.bits = np.packbits(lattice.reshape(-1))
        self.shapes, self.cells, self.vertex, self.edges = [], [], [], []
        self.quadric = [] if all(f"quadric{s}" in sample for s in range(levels + 1)) else None
        for s in range(levels + 1):
            surface = sample[f"surface{s}"]
            flat = np.flatnonzero(surface).astype(np.int64)
            self.shapes.append(surface.shape)
            # (n, 3) int32 surface cells, their (n, 3) float32 vertex offsets
            self.cells.append(np.stack(np.unravel_index(flat, surface.shape), 1).astype(np.int32))
            self.vertex.append(sample[f"vertex{s}"].reshape(-1, 3)[flat].astype(np.float32))
            if self.quadric is not None:
                self.quadric.append(sample[f"quadric{s}"].reshape(-1, 6)[flat].astype(np.float32))
            edge = sample[f"edge{s}"]
            self.edges.append([np.argwhere(edge[..., a]).astype(np.int32) for a in range(3)])

    def lattice(self) -> np.ndarray:
        return np.unpackbits(self.bits, count=int(np.prod(self.shape0))).reshape(
            self.shape0).astype(bool)

    def window(self, s: int, lo, size) -> dict:
        """Dense scale-s arrays of the box ``lo .. lo + size`` (scale-s points).

        The coarser inputs are pooled from the window itself: a ``lo`` that is a multiple of
        2**(levels - s) gives the lattice's own pyramid, any other ``lo`` that of the part
        moved by the difference (``TrainConfig.random_phase``). Returns {"grids": [G_s ..
        G_levels], "surface{s}", "vertex{s}", "edge{s}"} as ``make_crop`` reads them.
        """
        lo, size = np.asarray(lo), np.asarray(size)
        k = 2 ** s
        grids = occupancy_pyramid(take(self.lattice(), lo * k, size * k), self.levels)[s:]
        surface = np.zeros(tuple(size), bool)
        vertex = np.zeros(tuple(size) + (3,), np.float32)
        edge = np.zeros(tuple(size) + (3,), bool)
        local, keep = _inside_box(self.cells[s], lo, size)
        surface[tuple(local.T)] = True
        vertex[tuple(local.T)] = self.vertex[s][keep]
        out = {"grids": grids, f"surface{s}": surface, f"vertex{s}": vertex}
        if self.quadric is not None:
            quadric = np.zeros(tuple(size) + (6,), np.float32)
            quadric[tuple(local.T)] = self.quadric[s][keep]
            out[f"quadric{s}"] = quadric
        for a in range(3):
            local, _ = _inside_box(self.edges[s][a], lo, size)
            edge[tuple(local.T) + (a,)] = True
        out[f"edge{s}"] = edge
        return out


def _inside_box(points: np.ndarray, lo, size):
    """(points - lo) of the (n, 3) points inside the box, and the mask that selected them."""
    local = points.astype(np.int64) - lo
    keep = np.all((local >= 0) & (local < size), axis=1)
    return local[keep], keep
