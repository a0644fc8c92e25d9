"""Band evaluation: the network's spatial ops on the points near the surface only.

A binary lattice is mostly uniform space. A point whose whole receptive field is uniform has the
same features as a point of an infinite uniform volume of its type ("far inside"/"far outside").
Those features are periodic, not constant: sparse up-sampling re-expresses vertices in the
child's frame (period 2 per scale) and window attention depends on the position in the window,
so a far point's features are those of the periodic volume at ``p mod period``.

Rows. Features of one lattice are ``(R, C)`` rows:

* rows ``[0, T)`` are a **torus**: the ``2 P^3`` points of one period of a far-outside
  (type 0) and a far-inside (type 1) volume, with wrap-around neighbours. They are evaluated by the
  same layers in the same pass, so every layer's far features come for free and stay exact;
* rows ``[T, T + N_r)`` are the **band** of radius r: lattice points whose Chebyshev distance
  ``d`` to a point of the other type is <= r, sorted by ``d``, so the band of a smaller radius
  is a prefix (a crop is a slice) and a tensor's radius follows from its row count.

A neighbour lookup at a lattice point returns its band row if ``d <= r_in`` (the radius its source
was computed on), else the torus row of its type and phase. That is exact for points whose
receptive field is uniform, and the definition of the network's output otherwise: a band of
radius ``config.band_radius`` equals the dense evaluation when it covers the receptive field
(tests), and is an approximation of it for the long-reaching full model (snakes and windows reach
~5 points per layer). Training with band evaluation (``AGNDCCascade.forward_band``) makes
inference exact; for densely trained weights a wider band is closer and slower.

Ops with a ``radius`` compute that radius's rows from a source of any radius (early convolutions
grow the band 1, 2, 3 as their receptive field grows; the last layers shrink it to the surface
cells). Positions outside the lattice read the nearest lattice point, as ``DenseOps`` does.
Differentiable (training on the band is possible); under ``torch.inference_mode`` the
convolutions write into reused buffers instead.
"""

from __future__ import annotations

import numpy as np
import torch

from .common import (
    CELL_CORNERS,
    cell_surface,
    child_prediction,
    cube_offsets,
    lateral_axes,
    snake_corners,
)
from .layout import (  # noqa: F401  (re-exported)
    BandRows,
    half_band,
    snake_margin,
    surface_distance,
    torus_periods,
)

#: floats per gather buffer (32 MB): bounds memory, keeps the matmul operands cache-friendly
CHUNK_FLOATS = 1 << 23
#: convolutions with at most this many output channels are evaluated "project first": multiply
#: every row by all k^3 tap weights, then gather k^3 narrow rows (much less gathering)
PROJECT_FIRST_MAX = 2
#: narrower im2col matmuls are padded to this many output columns (CPU BLAS runs N = 6 about
#: 3x slower than N = 16)
MIN_MATMUL_COLUMNS = 16


class BandOps(BandRows):
    """Spatial ops over the band rows of one lattice (see module docstring).

    Args:
        kind: (X, Y, Z) bool tensor, the lattice's occupancy (type of every point).
        dist: (X, Y, Z) int tensor, Chebyshev distance to the nearest point of the other type
            (1 for points touching the surface), ``surface_distance``.
        radius: the widest band kept (points with ``dist <= radius``).
        period: P, the far field's period at this lattice (``torus_periods``).
        margin: how far outside the lattice lookups may reach without clamping (the snakes'
            reach); lookups use a copy of the row volume padded by it.
    """

    def __init__(self, kind: torch.Tensor, dist: torch.Tensor, radius: int, period: int,
                 margin: int = 8):
        device = kind.device
        self.shape = tuple(kind.shape)
        self.radius, self.margin = int(radius), int(margin)
        self.period = p = int(period)
        self.torus = 2 * p ** 3
        self.torus_coords = _grid_coords((p, p, p), device).repeat(2, 1)
        self.torus_type = torch.arange(2, device=device).repeat_interleave(p ** 3)
        self.half = self.coarser = None  # linked by the caller (scale_ops)
        flat = dist.clamp(max=radius + 1).reshape(-1)
        lin = torch.nonzero(flat <= radius).squeeze(1)
        lin = lin[torch.argsort(flat[lin], stable=True)]
        self.coords = _unravel(lin, self.shape)  # (N, 3) band points, nearest first
        band_d = flat[lin]
        self.counts = [self.torus + int((band_d <= r).sum()) for r in range(radius + 1)]
        self._radius_of_rows = {n: r for r, n in enumerate(self.counts)}
        rank = torch.full((flat.numel(),), -1, dtype=torch.int32, device=device)
        rank[lin] = torch.arange(self.torus, self.torus + lin.numel(), dtype=torch.int32,
                                 device=device)
        # torus row of every lattice point: its type's torus at its phase p mod P
        phase = [torch.arange(n, device=device) % p for n in self.shape]
        phase = (phase[0][:, None, None] * p + phase[1][None, :, None]) * p + phase[2]
        far = kind.long() * p ** 3 + phase
        self._dist, self._rank, self._far = flat, rank, far.reshape(-1).to(torch.int32)
        m = self.margin
        self._padded_shape = tuple(n + 2 * m for n in self.shape)
        self._strides = (self._padded_shape[1] * self._padded_shape[2], self._padded_shape[2], 1)
        self._volumes: dict[int, torch.Tensor] = {}
        self._neighbours: dict[tuple, torch.Tensor] = {}

    @classmethod
    def everywhere(cls, shape, period: int, device="cpu") -> BandOps:
        """Ops whose band holds every lattice point, in C order (rows of a dense array)."""
        ones = torch.ones(tuple(shape), dtype=torch.int32, device=device)
        return cls(torch.zeros(tuple(shape), dtype=torch.bool, device=device), ones, 1, period)

    # ------------------------------------------------------------------ rows and lookups
    def volume(self, radius: int) -> torch.Tensor:
        """(X + 2m, Y + 2m, Z + 2m) int32 flattened: the row each point reads from a source of
        ``radius``; the margin replicates the border (positions outside read the nearest)."""
        radius = min(radius, self.radius)
        if radius not in self._volumes:
            vol = torch.where(self._dist <= radius, self._rank, self._far).reshape(self.shape)
            m = self.margin
            idx = [torch.arange(-m, n + m, device=vol.device).clamp(0, n - 1) for n in self.shape]
            vol = vol[idx[0][:, None, None], idx[1][None, :, None], idx[2][None, None, :]]
            self._volumes[radius] = vol.reshape(-1)
        return self._volumes[radius]

    def padded_index(self, coords: torch.Tensor) -> torch.Tensor:
        """Linear index into ``volume`` of lattice points ``coords`` (..., 3), clamped to the
        margin (equivalent to clamping to the lattice: the margin replicates the border)."""
        m = self.margin
        hi = torch.tensor(self._padded_shape, device=coords.device) - 1
        c = torch.minimum((coords + m).clamp_min(0), hi)
        return (c[..., 0] * self._padded_shape[1] + c[..., 1]) * self._padded_shape[2] + c[..., 2]

    def lookup(self, coords: torch.Tensor, radius: int, types=None) -> torch.Tensor:
        """Rows of lattice points ``coords`` (..., 3) in a source of ``radius``.

        ``types`` None: real lattice points (outside ones read the nearest lattice point); else
        torus points of those types (broadcastable to coords[..., 0]), wrapped into one period.
        """
        if types is None:
            return self.volume(radius)[self.padded_index(coords)].long()
        p = self.period
        return types * p ** 3 + _linear(coords % p, (p, p, p))

    def parts(self, radius: int, chunk: int | None = None):
        """Yield (start, stop, coords, types) covering the rows of ``radius``: the torus, then
        band chunks of at most ``chunk`` rows (``types`` None for band rows)."""
        yield 0, self.torus, self.torus_coords, self.torus_type
        stop = self.rows(radius)
        step = chunk or max(stop, 1)
        for a in range(self.torus, stop, step):
            b = min(a + step, stop)
            yield a, b, self.coords[a - self.torus:b - self.torus], None

    def neighbours(self, k: int, radius: int, radius_in: int) -> torch.Tensor:
        """(rows(radius), k^3) int32 rows of each target's k^3 neighbourhood (cached)."""
        key = (k, radius, radius_in)
        if key not in self._neighbours:
            offsets = cube_offsets(k).to(self.coords.device)
            # band rows: offsets are affine in the padded volume (k // 2 < margin)
            step = (offsets * torch.tensor(self._strides, device=offsets.device)).sum(1)
            volume = self.volume(radius_in)
            parts = [self.lookup(self.torus_coords[:, None] + offsets, radius_in,
                                 self.torus_type[:, None]).int()]
            for _, _, coords, types in self.parts(radius, chunk=1 << 16):
                if types is None:
                    parts.append(volume[self.padded_index(coords)[:, None] + step])
            self._neighbours[key] = torch.cat(parts)
        return self._neighbours[key]

    # ------------------------------------------------------------------ bookkeeping
    def input(self, g=None) -> torch.Tensor:
        """(T, 1) occupancy rows of radius 0: the torus only, every band point reads its type."""
        return self.torus_type.to(torch.float32)[:, None]

    def resample(self, x: torch.Tensor, radius: int) -> torch.Tensor:
        """Rows of ``radius`` from a tensor of any radius (a crop, or far rows appended)."""
        r_in = self.radius_of(x)
        if radius <= r_in:
            return self.crop(x, radius)
        extra = self.coords[x.shape[0] - self.torus:self.rows(radius) - self.torus]
        return torch.cat([x, _rows(x, self.lookup(extra, r_in))])

    def to_dense(self, x: torch.Tensor) -> torch.Tensor:
        """(X, Y, Z, C) features of every lattice point (far points from the torus)."""
        m = self.margin
        rows = self.volume(self.radius_of(x)).reshape(self._padded_shape)
        rows = rows[m:m + self.shape[0], m:m + self.shape[1], m:m + self.shape[2]]
        return _rows(x, rows).reshape(*self.shape, x.shape[1])

    # ------------------------------------------------------------------ spatial ops
    def conv(self, x: torch.Tensor, conv: torch.nn.Conv3d, radius: int) -> torch.Tensor:
        """k x k x k convolution of rows ``x`` evaluated at the rows of ``radius``."""
        k, c_in, c_out = conv.kernel_size[0], conv.in_channels, conv.out_channels
        taps = k ** 3
        nbr = self.neighbours(k, radius, self.radius_of(x))
        n_out = nbr.shape[0]
        bias = conv.bias if conv.bias is not None else x.new_zeros(c_out)
        # (k^3 C_in, C_out), tap-major like cube_offsets
        weight = conv.weight.permute(2, 3, 4, 1, 0).reshape(taps * c_in, c_out)
        grad = torch.is_grad_enabled()
        if c_out <= PROJECT_FIRST_MAX:
            # (R_in k^3, C_out): every row times every tap's weights, then narrow gathers
            proj = x @ weight.reshape(taps, c_in, c_out).permute(1, 0, 2).reshape(c_in, -1)
            proj = proj.reshape(-1, c_out)
            tap = torch.arange(taps, device=x.device, dtype=torch.int32)
            step = max(1, CHUNK_FLOATS // (taps * c_out))
            pieces = [_rows(proj, nbr[a:a + step] * taps + tap).sum(1)
                      for a in range(0, n_out, step)]
            return torch.cat(pieces) + bias
        if c_out < MIN_MATMUL_COLUMNS and not grad:
            weight = torch.cat([weight, weight.new_zeros(taps * c_in,
                                                         MIN_MATMUL_COLUMNS - c_out)], 1)
            bias = torch.cat([bias, bias.new_zeros(MIN_MATMUL_COLUMNS - c_out)])
        step = max(1, CHUNK_FLOATS // (taps * c_in))
        if grad:
            pieces = [torch.addmm(bias, _rows(x, nbr[a:a + step]).reshape(-1, taps * c_in),
                                  weight)
                      for a in range(0, n_out, step)]
            return torch.cat(pieces)
        out = x.new_empty(n_out, weight.shape[1])
        buf = x.new_empty(min(step, n_out) * taps, c_in)
        for a in range(0, n_out, step):
            idx = nbr[a:a + step].reshape(-1)
            cols = torch.index_select(x, 0, idx, out=buf[:idx.numel()])
            torch.addmm(bias, cols.view(-1, taps * c_in), weight, out=out[a:a + step])
        return out[:, :c_out]

    def snake(self, y: torch.Tensor, offsets: torch.Tensor, axis: int, radius: int):
        """Sum over the taps of one snake branch (see ``DenseOps.snake``).

        Args:
            y: (R_in, K b) pre-projected rows; offsets: (rows(radius), 2, K), each at most
                ``margin - 1`` from the tap's lattice line.

        Returns:
            (rows(radius), b).
        """
        k = offsets.shape[-1]
        width = y.shape[1] // k
        r_in = self.radius_of(y)
        flat = y.reshape(-1, width)
        tap = torch.arange(k, device=y.device, dtype=torch.int32)
        volume = self.volume(r_in)
        lat_b, lat_c = lateral_axes(axis)
        stride = self._strides
        # linear offsets in the padded volume of each tap along the axis, and of the 4 corners
        tap_step = (tap - k // 2) * stride[axis]
        corner = torch.tensor([0, stride[lat_b], stride[lat_c], stride[lat_b] + stride[lat_c]],
                              device=y.device, dtype=torch.int32)
        pieces = []
        step = max(1, CHUNK_FLOATS // (4 * k * width))
        grad = torch.is_grad_enabled()
        if not grad:  # reused buffers: fresh allocations page-fault on every chunk
            out = y.new_empty(self.rows(radius), width)
            buf = y.new_empty(max(self.torus, min(step, self.rows(radius))) * 4 * k, width)
        for a, b, coords, types in self.parts(radius, chunk=step):
            if types is None:
                base = offsets[a:b].detach().floor()
                frac = offsets[a:b] - base
                base = base.int()
                # (n, K, 4) linear positions: centre + tap + lateral drift + corner
                lin = (self.padded_index(coords).int()[:, None] + tap_step
                       + base[:, 0] * stride[lat_b] + base[:, 1] * stride[lat_c])
                rows = volume[(lin[..., None] + corner).reshape(-1)]
                weights = _bilinear(frac)
            else:
                corners, weights = snake_corners(coords, offsets[a:b], axis)
                rows = self.lookup(corners, r_in, types[:, None, None]).reshape(-1).int()
            idx = (rows.view(b - a, k, 4) * k + tap[:, None]).reshape(-1)
            weights = weights.reshape(b - a, 1, 4 * k)
            if grad:
                values = flat.index_select(0, idx).reshape(b - a, 4 * k, width)
                pieces.append(torch.bmm(weights, values)[:, 0])
                continue
            values = torch.index_select(flat, 0, idx, out=buf[:idx.numel()])
            torch.bmm(weights, values.view(b - a, 4 * k, width), out=out[a:b, None])
        return torch.cat(pieces) if grad else out

    def windows(self, x: torch.Tensor, window: int, shift: int, attend, radius: int):
        """``attend`` over the windows holding the rows of ``radius`` (see DenseOps.windows)."""
        w = window
        r_in = self.radius_of(x)
        local = _grid_coords((w, w, w), x.device)  # (w^3, 3)
        pieces = []
        for _, _, coords, types in self.parts(radius):
            cell = torch.div(coords + shift, w, rounding_mode="floor")  # window index per axis
            span = cell.amax(0) + 1 if coords.numel() else torch.ones(3, dtype=torch.long)
            device = coords.device
            key = _linear(cell, tuple(int(s) for s in span))
            if types is not None:
                key = key + types * int(span.prod())
            uniq, inverse = torch.unique(key, return_inverse=True)
            first = torch.zeros_like(uniq).scatter_(0, inverse,
                                                    torch.arange(len(key), device=device))
            # (W, w^3, 3) token coordinates of each window
            origin = cell[first] * w - shift
            tokens = origin[:, None, :] + local
            t = None if types is None else types[first][:, None]
            token_rows = self.lookup(tokens, r_in, t)
            slot = _linear((coords + shift) % w, (w, w, w))
            # targets grouped by window, so each chunk of windows serves a contiguous range
            order = torch.argsort(inverse)
            ends = torch.searchsorted(inverse[order], torch.arange(len(uniq) + 1, device=device))
            ends = ends.tolist()
            out = None
            step = max(1, CHUNK_FLOATS // (w ** 3 * x.shape[1] * 4))
            for i in range(0, len(uniq), step):
                attended = attend(_rows(x, token_rows[i:i + step]))  # (W, w^3, C')
                if out is None:
                    out = attended.new_empty(len(key), attended.shape[-1])
                mine = order[ends[i]:ends[min(i + step, len(uniq))]]
                flat = attended.reshape(-1, attended.shape[-1])
                out[mine] = flat.index_select(0, (inverse[mine] - i) * w ** 3 + slot[mine])
            pieces.append(out)
        return torch.cat(pieces)

    def down(self, x: torch.Tensor, radius: int) -> torch.Tensor:
        """Mean of each 2x2x2 block, evaluated at ``half``'s rows of ``radius``."""
        half, r_in = self.half, self.radius_of(x)
        corners = CELL_CORNERS.to(x.device)
        out = []
        for _, _, coords, types in half.parts(radius):
            t = None if types is None else types[:, None]
            out.append(_rows(x, self.lookup(2 * coords[:, None] + corners, r_in, t)).mean(1))
        return torch.cat(out)

    def up(self, x_half: torch.Tensor, radius: int) -> torch.Tensor:
        """Nearest-neighbour up-sampling of ``half`` rows to this lattice's rows of ``radius``."""
        return _rows(x_half, self._parent_rows(self.half, self.half.radius_of(x_half), radius))

    def upsample_prediction(self, p: torch.Tensor, radius: int) -> torch.Tensor:
        """Sparse up-sampling of ``coarser`` prediction rows (see DenseOps.upsample_prediction)."""
        coarse = self.coarser
        r_c = coarse.radius_of(p)
        q = torch.sigmoid(p[:, 3:])
        corners = CELL_CORNERS.to(p.device)
        hi = torch.tensor(coarse.shape, device=p.device) - 1
        masks = []
        for _, _, coords, types in coarse.parts(r_c):
            t = None if types is None else types[:, None]
            mask = cell_surface(_rows(q, coarse.lookup(coords[:, None] + corners, r_c, t)))
            if types is None:
                mask &= (coords < hi).all(1)  # cells need their far corner in the lattice
            masks.append(mask)
        mask = torch.cat(masks)
        parent = self._parent_rows(coarse, r_c, radius)
        child = torch.cat([coords % 2 for _, _, coords, _ in self.parts(radius)])
        return child_prediction(_rows(p, parent), mask[parent], child)

    def _parent_rows(self, other: BandOps, r_other: int, radius: int) -> torch.Tensor:
        """Rows in ``other`` (the 2x coarser lattice) of the parents of our rows of ``radius``."""
        out = []
        for _, _, coords, types in self.parts(radius):
            out.append(other.lookup(torch.div(coords, 2, rounding_mode="floor"), r_other, types))
        return torch.cat(out)


def _rows(x: torch.Tensor, index: torch.Tensor) -> torch.Tensor:
    """x[index] for an (R, C) row tensor and an integer index of any shape (index_select is
    several times faster than advanced indexing on CPU)."""
    return x.index_select(0, index.reshape(-1)).reshape(*index.shape, x.shape[1])


def _bilinear(frac: torch.Tensor) -> torch.Tensor:
    """(n, 2, K) fractional lateral offsets -> (n, K, 4) bilinear weights of the corners
    (0, 0), (1, 0), (0, 1), (1, 1)."""
    fb, fc = frac[:, 0], frac[:, 1]
    return torch.stack([(1 - fb) * (1 - fc), fb * (1 - fc), (1 - fb) * fc, fb * fc], -1)


# ---------------------------------------------------------------------- building the pyramid


def scale_ops(occupancy: np.ndarray, radius: int, period: int, half_period: int | None = None,
              margin: int = 8, device="cpu") -> BandOps:
    """BandOps of one scale's lattice; with ``half_period`` also its CRPM ``half`` lattice.

    ``half`` is the 2x coarser lattice with a band *derived from this band* (a coarse point is
    near the surface if one of its 8 children is), so every fine band point's block mean and
    up-sampled parent are band rows, even where OR-pooling closes thin gaps. Its radius covers
    what CRPM reads (``CRPM.radii``).
    """
    occupancy = np.asarray(occupancy, dtype=bool)
    dist = surface_distance(occupancy)
    ops = BandOps(torch.from_numpy(occupancy).to(device), torch.from_numpy(dist).to(device),
                  radius, period, margin)
    if half_period is not None:
        coarse, coarse_dist, coarse_radius = half_band(occupancy, dist, radius)
        ops.half = BandOps(torch.from_numpy(coarse).to(device),
                           torch.from_numpy(coarse_dist).to(device), coarse_radius, half_period,
                           margin)
    return ops


def _grid_coords(shape, device) -> torch.Tensor:
    axes = [torch.arange(n, device=device) for n in shape]
    return torch.stack(torch.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)


def _linear(coords: torch.Tensor, shape) -> torch.Tensor:
    return (coords[..., 0] * shape[1] + coords[..., 1]) * shape[2] + coords[..., 2]


def _unravel(lin: torch.Tensor, shape) -> torch.Tensor:
    z = lin % shape[2]
    y = (lin // shape[2]) % shape[1]
    return torch.stack([lin // (shape[1] * shape[2]), y, z], -1)
