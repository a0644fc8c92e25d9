"""Band evaluation in numpy: the spatial ops of the network on the points near the surface.

The same rows, torus and lookups as the torch ``nn/band_ops.py`` (its module docstring defines
them), written for inference only: no gradients, int32 index tables built once per lattice and
reused by every layer, and gathers done in cache-sized chunks straight into the matmul's input.

Rows of a lattice's features are ``(R, C)`` float32: rows ``[0, T)`` are the far-field torus
(``2 P^3`` points of a far-outside and a far-inside periodic volume), rows ``[T, T + N_r)`` the band
points within Chebyshev distance ``r`` of the surface, nearest first, so a tensor's radius follows
from its row count and a crop is a slice.
"""

from __future__ import annotations

import numpy as np

from ..nn.layout import (
    CELL_CORNERS,
    CELL_EDGE_CORNERS,
    SNAKE_CORNERS,
    BandRows,
    cube_offsets,
    half_band,
    lateral_axes,
    surface_distance,
)
from .parallel import for_chunks, scratch

#: output rows per gather-and-multiply chunk: the gathered (rows, k^3 C) block stays in the
#: cache between the gather and the matmul, and no large temporary is allocated (a fresh
#: 30 MB array costs more in page faults than the gather that fills it)
CHUNK_ROWS = 1024
#: band rows per chunk of a snake: its index arithmetic is a dozen small element-wise passes, so
#: larger chunks than a convolution's (whose gathered block must stay in cache) pay less overhead
SNAKE_CHUNK_ROWS = 8192
#: convolutions with at most this many output channels are evaluated "project first": every row
#: times every tap's weights, then k^3 narrow gathers summed. A gather costs per row, not per
#: byte (measured: 17 -> 4 and 16 -> 6 run 1.3x and 8x slower this way than by im2col)
PROJECT_FIRST_MAX = 2


class Band(BandRows):
    """Index tables of one lattice's band (see ``nn/band_ops.BandOps`` for the definitions).

    Args:
        kind: (X, Y, Z) bool, the lattice's occupancy (type of every point).
        dist: (X, Y, Z) int, Chebyshev distance to the nearest point of the other type.
        radius: the widest band kept; period: P, the far field's period at this lattice;
        margin: how far outside the lattice lookups may reach (a padded copy of the row volume).
    """

    def __init__(self, kind: np.ndarray, dist: np.ndarray, radius: int, period: int,
                 margin: int = 8):
        self.shape = tuple(int(n) for n in kind.shape)
        self.radius, self.margin = int(radius), int(margin)
        self.period = p = int(period)
        self.torus = 2 * p ** 3
        self.torus_coords = np.tile(grid_coords((p, p, p)), (2, 1))
        self.torus_type = np.repeat(np.arange(2), p ** 3)
        self.half = self.coarser = None  # linked by the caller (scale_band)
        flat = np.minimum(dist.reshape(-1), radius + 1)
        lin = np.flatnonzero(flat <= radius)
        lin = lin[np.argsort(flat[lin], kind="stable")]
        self.coords = np.stack(np.unravel_index(lin, self.shape), -1)  # (N, 3), nearest first
        band_d = flat[lin]
        self.counts = [self.torus + int(np.count_nonzero(band_d <= r))
                       for r in range(radius + 1)]
        self._radius_of_rows = {n: r for r, n in enumerate(self.counts)}
        rank = np.full(flat.size, -1, dtype=np.int32)
        rank[lin] = np.arange(self.torus, self.torus + lin.size, dtype=np.int32)
        phase = [np.arange(n) % p for n in self.shape]
        phase = (phase[0][:, None, None] * p + phase[1][None, :, None]) * p + phase[2]
        far = kind.astype(np.int64) * p ** 3 + phase
        self._dist, self._rank, self._far = flat, rank, far.reshape(-1).astype(np.int32)
        m = self.margin
        self.padded_shape = tuple(n + 2 * m for n in self.shape)
        self.strides = (self.padded_shape[1] * self.padded_shape[2], self.padded_shape[2], 1)
        self._volumes: dict[int, np.ndarray] = {}
        self._neighbours: dict[tuple, np.ndarray] = {}
        self._steps: dict[int, np.ndarray] = {}
        self._band_index = None

    @classmethod
    def everywhere(cls, shape, period: int) -> Band:
        """A band holding every lattice point, in C order (rows of a dense array)."""
        shape = tuple(shape)
        return cls(np.zeros(shape, dtype=bool), np.ones(shape, dtype=np.int32), 1, period)

    # ------------------------------------------------------------------ rows and lookups
    def volume(self, radius: int) -> np.ndarray:
        """Flat int32 padded volume: the row each point reads from a source of ``radius``;
        the margin replicates the border (positions outside read the nearest point)."""
        radius = min(radius, self.radius)
        if radius not in self._volumes:
            vol = np.where(self._dist <= radius, self._rank, self._far).reshape(self.shape)
            vol = np.pad(vol, self.margin, mode="edge").reshape(-1)
            self._volumes[radius] = vol.astype(np.int32)
        return self._volumes[radius]

    def padded_index(self, coords: np.ndarray) -> np.ndarray:
        """Linear index into ``volume`` of lattice points ``coords`` (..., 3), clamped."""
        m = self.margin
        c = np.clip(coords + m, 0, np.array(self.padded_shape) - 1)
        return (c[..., 0] * self.padded_shape[1] + c[..., 1]) * self.padded_shape[2] + c[..., 2]

    def band_index(self) -> np.ndarray:
        """(N,) int64 padded index of every band point (cached)."""
        if self._band_index is None:
            self._band_index = self.padded_index(self.coords)
        return self._band_index

    def lookup(self, coords: np.ndarray, radius: int, types=None) -> np.ndarray:
        """Rows of lattice points ``coords`` (..., 3) in a source of ``radius``; with ``types``
        torus points of those types, wrapped into one period."""
        if types is None:
            return self.volume(radius)[self.padded_index(coords)].astype(np.intp)
        p = self.period
        return types * p ** 3 + linear(coords % p, (p, p, p))

    def parts(self, radius: int):
        """(coords, types) of the torus rows, then (coords, None) of the band rows of radius."""
        yield self.torus_coords, self.torus_type
        yield self.coords[:self.rows(radius) - self.torus], None

    def neighbours(self, k: int, radius_in: int, a: int, b: int) -> np.ndarray:
        """(b - a, k^3) intp rows of the k^3 neighbourhood of output rows [a, b), read from a
        source of ``radius_in``. Built per chunk, not stored: reading a stored table moves as
        many bytes as the lookup in the row volume it replaces, and a table per input radius
        would hold ~100 MB per million band rows."""
        t = self.torus
        parts = []
        if a < t:
            key = (k, radius_in)
            if key not in self._neighbours:  # the torus's own table: 2 P^3 rows, kept
                self._neighbours[key] = self.lookup(
                    self.torus_coords[:, None] + cube_offsets(k), radius_in,
                    self.torus_type[:, None]).astype(np.intp)
            parts.append(self._neighbours[key][a:min(b, t)])
        if b > t:
            # band rows: offsets are affine in the padded volume (k // 2 < margin); the k^3
            # steps once per kernel size, not per chunk
            if k not in self._steps:
                self._steps[k] = cube_offsets(k) @ np.array(self.strides)
            centre = self.band_index()[max(a, t) - t:b - t]
            parts.append(self.volume(radius_in)[centre[:, None] + self._steps[k]]
                         .astype(np.intp))
        return parts[0] if len(parts) == 1 else np.concatenate(parts)

    # ------------------------------------------------------------------ bookkeeping
    def input(self) -> np.ndarray:
        """(T, 1) occupancy rows of radius 0: the torus only, every band point reads its type."""
        return self.torus_type.astype(np.float32)[:, None]

    def resample(self, x: np.ndarray, radius: int) -> np.ndarray:
        """Rows of ``radius`` from rows of any radius (a crop, or far rows appended)."""
        r_in = self.radius_of(x)
        if radius <= r_in:
            return self.crop(x, radius)
        extra = self.coords[x.shape[0] - self.torus:self.rows(radius) - self.torus]
        return np.concatenate([x, x[self.lookup(extra, r_in)]])

    def to_dense(self, x: np.ndarray) -> np.ndarray:
        """(X, Y, Z, C) features of every lattice point (far points from the torus)."""
        m = self.margin
        rows = self.volume(self.radius_of(x)).reshape(self.padded_shape)
        rows = rows[m:m + self.shape[0], m:m + self.shape[1], m:m + self.shape[2]]
        return x[rows]

    # ------------------------------------------------------------------ spatial ops
    def conv(self, x: np.ndarray, conv, radius: int, tick=None, out=None) -> np.ndarray:
        """k x k x k convolution (a ``runtime.network.Conv``) of rows ``x`` at the rows of
        ``radius`` (into ``out``, (rows(radius), C_out), when given)."""
        r_in = self.radius_of(x)
        taps, c_out, n_out = conv.k ** 3, conv.c_out, self.rows(radius)
        if out is None:
            out = np.empty((n_out, c_out), dtype=np.float32)
        if c_out <= PROJECT_FIRST_MAX and c_out < x.shape[1]:
            # (R_in k^3, C_out): every row times every tap's weights, then narrow gathers,
            # summed over the taps by a matmul with a 0/1 matrix (faster than a strided sum)
            proj = (x @ conv.project_first).reshape(-1, c_out)
            tap = np.arange(taps, dtype=np.intp)

            def work(a, b):
                idx = (self.neighbours(conv.k, r_in, a, b) * taps + tap).reshape(-1)
                cols = np.take(proj, idx, axis=0, out=scratch("proj", (idx.size, c_out)))
                np.matmul(cols.reshape(b - a, -1), conv.tap_sum, out=out[a:b])
        else:
            width = taps * x.shape[1]

            def work(a, b):
                idx = self.neighbours(conv.k, r_in, a, b).reshape(-1)
                cols = np.take(x, idx, axis=0, out=scratch("conv", (idx.size, x.shape[1])))
                np.matmul(cols.reshape(-1, width), conv.weight, out=out[a:b])

        for_chunks(n_out, CHUNK_ROWS, work, tick)
        out += conv.bias
        return out

    def snake(self, y: np.ndarray, offsets: np.ndarray, axis: int, radius: int,
              out=None) -> np.ndarray:
        """Sum over the taps of one snake branch (see ``nn/band_ops.BandOps.snake``).

        Args:
            y: (R_in, K b) pre-projected rows; offsets: (rows(radius), 2, K) cumulative lateral
                offsets, each at most ``margin - 1`` from the tap's lattice line; out: where to
                write the result, when given.

        Returns:
            (rows(radius), b) float32.
        """
        k = offsets.shape[-1]
        width = y.shape[1] // k
        r_in = self.radius_of(y)
        flat = y.reshape(-1, width)
        tap = np.arange(k)
        lat_b, lat_c = lateral_axes(axis)
        n_rows = self.rows(radius)
        if out is None:
            out = np.empty((n_rows, width), dtype=np.float32)
        # the torus: corners wrapped into one period
        t = self.torus
        corners, weights = snake_corners(self.torus_coords, offsets[:t], axis)
        rows = self.lookup(corners, r_in, self.torus_type[:, None, None])
        out[:t] = _weighted_taps(flat, rows * k + tap[:, None], weights)
        # band rows: linear positions in the padded volume (centre + tap + drift + corner)
        volume = self.volume(r_in)
        stride = self.strides
        tap_step = (tap - k // 2) * stride[axis]
        corner = np.array([0, stride[lat_b], stride[lat_c], stride[lat_b] + stride[lat_c]])
        centre = self.band_index()

        def work(a, b):
            a, b = a + t, b + t
            base = np.floor(offsets[a:b])
            frac = offsets[a:b] - base
            base = base.astype(np.intp)
            lin = (centre[a - t:b - t, None] + tap_step + base[:, 0] * stride[lat_b]
                   + base[:, 1] * stride[lat_c])
            rows = volume[lin[..., None] + corner]
            out[a:b] = _weighted_taps(flat, rows * k + tap[:, None], bilinear(frac))

        for_chunks(n_rows - t, SNAKE_CHUNK_ROWS, work)
        return out

    def windows(self, x: np.ndarray, window: int, shift: int, attend, radius: int):
        """``attend`` over the windows holding the rows of ``radius`` (DenseOps.windows):
        every window's ``window^3`` tokens are gathered, attended, and each target row takes
        its own token's output."""
        w = window
        r_in = self.radius_of(x)
        local = grid_coords((w, w, w))
        pieces = []
        for coords, types in self.parts(radius):
            cell = np.floor_divide(coords + shift, w)
            span = cell.max(0) + 1 if len(coords) else np.ones(3, dtype=np.int64)
            key = linear(cell, tuple(int(s) for s in span))
            if types is not None:
                key = key + types * int(np.prod(span))
            uniq, first, inverse = np.unique(key, return_index=True, return_inverse=True)
            origin = cell[first] * w - shift
            tokens = origin[:, None, :] + local  # (W, w^3, 3)
            t = None if types is None else types[first][:, None]
            token_rows = self.lookup(tokens, r_in, t)
            attended = attend(x, token_rows)  # (W, w^3, C')
            slot = linear((coords + shift) % w, (w, w, w))
            flat = attended.reshape(-1, attended.shape[-1])
            pieces.append(flat[inverse.reshape(-1) * w ** 3 + slot])
        return np.concatenate(pieces)

    def down(self, x: np.ndarray, radius: int) -> np.ndarray:
        """Mean of each 2x2x2 block, evaluated at ``half``'s rows of ``radius``."""
        r_in = self.radius_of(x)
        out = []
        for coords, types in self.half.parts(radius):
            t = None if types is None else types[:, None]
            out.append(x[self.lookup(2 * coords[:, None] + CELL_CORNERS, r_in, t)].mean(1))
        return np.concatenate(out)

    def up(self, x_half: np.ndarray, radius: int) -> np.ndarray:
        """Nearest-neighbour up-sampling of ``half`` rows to this lattice's rows of ``radius``."""
        return x_half[self._parent_rows(self.half, self.half.radius_of(x_half), radius)]

    def upsample_prediction(self, p: np.ndarray, radius: int) -> np.ndarray:
        """Sparse up-sampling of ``coarser`` prediction rows (DenseOps.upsample_prediction)."""
        coarse = self.coarser
        r_c = coarse.radius_of(p)
        q = sigmoid(p[:, 3:])
        hi = np.array(coarse.shape) - 1
        masks = []
        for coords, types in coarse.parts(r_c):
            t = None if types is None else types[:, None]
            mask = cell_surface(q[coarse.lookup(coords[:, None] + CELL_CORNERS, r_c, t)])
            if types is None:
                mask &= (coords < hi).all(1)  # cells need their far corner in the lattice
            masks.append(mask)
        mask = np.concatenate(masks)
        parent = self._parent_rows(coarse, r_c, radius)
        child = np.concatenate([coords % 2 for coords, _ in self.parts(radius)])
        return child_prediction(p[parent], mask[parent], child)

    def _parent_rows(self, other: Band, r_other: int, radius: int) -> np.ndarray:
        """Rows in ``other`` (the 2x coarser lattice) of the parents of our rows of ``radius``."""
        return np.concatenate([other.lookup(coords // 2, r_other, types)
                               for coords, types in self.parts(radius)])


def scale_band(occupancy: np.ndarray, radius: int, period: int, half_period: int | None = None,
               margin: int = 8) -> Band:
    """The Band of one scale's lattice; with ``half_period`` also its CRPM ``half`` lattice."""
    occupancy = np.asarray(occupancy, dtype=bool)
    dist = surface_distance(occupancy)
    band = Band(occupancy, dist, radius, period, margin)
    if half_period is not None:
        coarse, coarse_dist, coarse_radius = half_band(occupancy, dist, radius)
        band.half = Band(coarse, coarse_dist, coarse_radius, half_period, margin)
    return band


# ---------------------------------------------------------------------- geometry


def snake_corners(coords: np.ndarray, offsets: np.ndarray, axis: int):
    """Integer corners (N, K, 4, 3) and bilinear weights (N, K, 4) of every tap of a snake
    centred on ``coords`` (N, 3) with lateral ``offsets`` (N, 2, K) (``nn/common.py``)."""
    n, _, k = offsets.shape
    lat_b, lat_c = lateral_axes(axis)
    base = np.floor(offsets)
    frac = offsets - base
    pos = np.repeat(coords[:, None, :], k, axis=1)
    pos[:, :, axis] += np.arange(k) - k // 2
    pos[:, :, lat_b] += base[:, 0].astype(np.int64)
    pos[:, :, lat_c] += base[:, 1].astype(np.int64)
    corners = np.repeat(pos[:, :, None, :], 4, axis=2)
    corners[..., lat_b] += SNAKE_CORNERS[:, 0]
    corners[..., lat_c] += SNAKE_CORNERS[:, 1]
    return corners, bilinear(frac)


def bilinear(frac: np.ndarray) -> np.ndarray:
    """(n, 2, K) fractional lateral offsets -> (n, K, 4) weights of the SNAKE_CORNERS."""
    fb, fc = frac[:, 0], frac[:, 1]
    return np.stack([(1 - fb) * (1 - fc), fb * (1 - fc), (1 - fb) * fc, fb * fc], -1)


def _weighted_taps(flat: np.ndarray, index: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """sum over taps and corners of ``weights`` (n, K, 4) times rows ``flat[index]``."""
    n = index.shape[0]
    rows = _as_row_elements(flat)
    if rows is None:
        values = np.take(flat, index.reshape(-1), axis=0)
    else:  # one element per row: numpy's 1-D take is ~1.6x faster than a row take
        values = np.take(rows, index.reshape(-1)).view(np.float32)
    values = values.reshape(n, -1, flat.shape[1])
    return np.matmul(weights.reshape(n, 1, -1).astype(np.float32, copy=False), values)[:, 0]


#: numpy dtypes as wide as a row of 1, 2 or 4 float32 channels
_ROW_DTYPES = {1: np.float32, 2: np.float64, 4: np.complex128}


def _as_row_elements(flat: np.ndarray):
    """A 1-D view of a C-contiguous (R, C) float32 array with one element per row, or None."""
    dtype = _ROW_DTYPES.get(flat.shape[1])
    if dtype is None or not flat.flags.c_contiguous:
        return None
    return flat.view(dtype).reshape(-1)


def cell_surface(q_corners: np.ndarray) -> np.ndarray:
    """(..., 8, 3) edge probabilities at a cell's corners -> (...) bool: any edge > 0.5."""
    best = [q_corners[..., list(idx), a].max(-1) for a, idx in enumerate(CELL_EDGE_CORNERS)]
    return np.stack(best, -1).max(-1) > 0.5


def child_prediction(p: np.ndarray, mask: np.ndarray, child: np.ndarray) -> np.ndarray:
    """A coarse cell's prediction re-expressed in a child cell (``nn/common.child_prediction``)."""
    vertex = 2.0 * p[..., :3] + 0.5 - child.astype(np.float32)
    out = np.concatenate([vertex, sigmoid(p[..., 3:])], -1)
    return (out * mask[..., None]).astype(np.float32)


def sigmoid(x: np.ndarray) -> np.ndarray:
    """Logistic function into a new float32 array (one temporary, not four)."""
    out = np.negative(x, dtype=np.float32)
    np.exp(out, out=out)
    out += 1.0
    return np.reciprocal(out, out=out)


def grid_coords(shape) -> np.ndarray:
    return np.stack(np.meshgrid(*[np.arange(n) for n in shape], indexing="ij"), -1).reshape(-1, 3)


def linear(coords: np.ndarray, shape) -> np.ndarray:
    return (coords[..., 0] * shape[1] + coords[..., 1]) * shape[2] + coords[..., 2]
