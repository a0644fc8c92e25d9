"""Spatial ops on dense channel-last features ``(B, X, Y, Z, C)``: the training and reference path.

Plain torch (``F.conv3d``, replicate padding, reshapes into windows, ``F.grid_sample`` for the
snakes), so it is the obviously-correct evaluation that ``BandOps`` is tested against. Borders
replicate the nearest grid point (see ``common.py``). ``radius`` arguments exist for interface
parity with ``BandOps`` and are ignored here.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from .common import CELL_CORNERS, cell_surface, child_prediction, lateral_axes

#: CELL_CORNERS as Python ints: slicing with them keeps the step traceable by torch.compile
#: (it traces a tensor's or numpy array's ``tolist`` as a data-dependent break)
_CORNER_TUPLES = tuple(tuple(int(v) for v in c) for c in CELL_CORNERS.tolist())


def replicate_pad(x_cf: torch.Tensor, lows, highs) -> torch.Tensor:
    """(B, C, X, Y, Z) padded by repeating its border planes: ``lows[a]`` before and
    ``highs[a]`` after the lattice along spatial axis a (``F.pad(mode="replicate")``).

    Under torch.compile the same values are built by concatenation: inductor fails on a
    replicate ``F.pad`` fed by the cascade's nearest-neighbour up-sampling. Eager keeps
    ``F.pad``, whose backward is faster on the CPU (concatenation: +12 % per training step)
    and sums gradients in the order earlier checkpoints were trained with.
    """
    if not torch.compiler.is_compiling():
        pads = [p for lo, hi in reversed(list(zip(lows, highs))) for p in (lo, hi)]
        return F.pad(x_cf, pads, mode="replicate")
    for a, (lo, hi) in enumerate(zip(lows, highs)):
        if lo or hi:
            dim, n = a + 2, x_cf.shape[a + 2]
            x_cf = torch.cat([x_cf.narrow(dim, 0, 1)] * lo + [x_cf]
                             + [x_cf.narrow(dim, n - 1, 1)] * hi, dim)
    return x_cf


class DenseOps:
    """Ops of one lattice of spatial shape ``shape``; ``half`` is the lattice halved."""

    def __init__(self, shape):
        self.shape = tuple(int(n) for n in shape)
        self.radius = 0
        self._half = None

    @property
    def half(self) -> DenseOps:
        """The 2x coarser lattice (CRPM's inner resolution, and the next cascade scale)."""
        if self._half is None:
            if any(n % 2 for n in self.shape):
                raise ValueError(f"lattice {self.shape} cannot be halved")
            self._half = DenseOps([n // 2 for n in self.shape])
        return self._half

    coarser = half

    # ------------------------------------------------------------------ bookkeeping (no-ops)
    def crop(self, x, radius):
        return x

    def resample(self, x, radius):
        return x

    def input(self, g: torch.Tensor) -> torch.Tensor:
        """(B, X, Y, Z) occupancy -> (B, X, Y, Z, 1) float features."""
        return g.to(torch.float32)[..., None]

    # ------------------------------------------------------------------ spatial ops
    def conv(self, x: torch.Tensor, conv: torch.nn.Conv3d, radius=None) -> torch.Tensor:
        """k x k x k convolution, stride 1, replicate padding."""
        pad = conv.kernel_size[0] // 2
        # (B, C, X, Y, Z)
        x_cf = x.permute(0, 4, 1, 2, 3)
        if pad:
            x_cf = replicate_pad(x_cf, (pad,) * 3, (pad,) * 3)
        return F.conv3d(x_cf, conv.weight, conv.bias).permute(0, 2, 3, 4, 1)

    def snake(self, y: torch.Tensor, offsets: torch.Tensor, axis: int, radius=None):
        """Sum over the taps of one snake branch of the pre-projected features.

        Each tap is a ``grid_sample`` of its own projected channels at its sample points (on
        a lattice line along ``axis``, so the trilinear weights reduce to bilinear ones across
        the two lateral axes); ``padding_mode="border"`` clamps a point to the lattice, which
        is the replicate border. One fused call for all taps (they are stacked in the batch):
        3-5x faster on the CPU than gathering 4 corners per tap, with the same values.

        Args:
            y: (B, X, Y, Z, K * b) features already multiplied by each tap's weights.
            offsets: (B, X, Y, Z, 2, K) cumulative lateral offsets.

        Returns:
            (B, X, Y, Z, b).
        """
        bsz, nx, ny, nz, kb = y.shape
        k = offsets.shape[-1]
        b = kb // k
        lat_b, lat_c = lateral_axes(axis)
        # (B K, b, X, Y, Z): tap t's projected channels as grid_sample's input
        source = y.reshape(bsz, nx, ny, nz, k, b).permute(0, 4, 5, 1, 2, 3)
        source = source.reshape(bsz * k, b, nx, ny, nz)
        axes = [torch.arange(n, device=y.device, dtype=offsets.dtype) for n in self.shape]
        point = torch.stack(torch.meshgrid(*axes, indexing="ij"), 0)  # (3, X, Y, Z)
        lateral = offsets.permute(4, 0, 5, 1, 2, 3)  # (2, B, K, X, Y, Z)
        taps = torch.arange(k, device=y.device, dtype=offsets.dtype) - k // 2
        position = [point[a].expand(bsz, k, nx, ny, nz) for a in range(3)]
        position[axis] = position[axis] + taps.reshape(1, k, 1, 1, 1)
        position[lat_b] = position[lat_b] + lateral[0]
        position[lat_c] = position[lat_c] + lateral[1]
        # grid_sample's last axis is (W, H, D) = (Z, Y, X), normalised to [-1, 1] (align_corners)
        grid = torch.stack([position[a] * (2.0 / max(self.shape[a] - 1, 1)) - 1.0
                            for a in (2, 1, 0)], -1)
        out = F.grid_sample(source, grid.reshape(bsz * k, nx, ny, nz, 3), mode="bilinear",
                            padding_mode="border", align_corners=True)  # (B K, b, X, Y, Z)
        return out.reshape(bsz, k, b, nx, ny, nz).sum(1).permute(0, 2, 3, 4, 1)

    def windows(self, x: torch.Tensor, window: int, shift: int, attend, radius=None):
        """Apply ``attend`` to every window of ``window^3`` points (windows start at -shift).

        Args:
            x: (B, X, Y, Z, C); attend: (W, window^3, C) -> (W, window^3, C').

        Returns:
            (B, X, Y, Z, C').
        """
        bsz, nx, ny, nz, c = x.shape
        w = window
        pads = [(shift, (-(n + shift)) % w) for n in (nx, ny, nz)]
        # (B, C, X', Y', Z')
        x_cf = replicate_pad(x.permute(0, 4, 1, 2, 3), *zip(*pads))
        mx, my, mz = (s // w for s in x_cf.shape[2:])
        # (B, C, mx, w, my, w, mz, w) -> (B mx my mz, w^3, C)
        tokens = x_cf.reshape(bsz, c, mx, w, my, w, mz, w).permute(0, 2, 4, 6, 3, 5, 7, 1)
        out = attend(tokens.reshape(-1, w ** 3, c))
        c_out = out.shape[-1]
        out = out.reshape(bsz, mx, my, mz, w, w, w, c_out).permute(0, 1, 4, 2, 5, 3, 6, 7)
        out = out.reshape(bsz, mx * w, my * w, mz * w, c_out)
        return out[:, shift:shift + nx, shift:shift + ny, shift:shift + nz]

    def down(self, x: torch.Tensor, radius=None) -> torch.Tensor:
        """(B, X, Y, Z, C) -> (B, X/2, Y/2, Z/2, C): mean of each 2x2x2 block."""
        bsz, nx, ny, nz, c = x.shape
        return x.reshape(bsz, nx // 2, 2, ny // 2, 2, nz // 2, 2, c).mean((2, 4, 6))

    def up(self, x_half: torch.Tensor, radius=None) -> torch.Tensor:
        """(B, X/2, Y/2, Z/2, C) on ``half`` -> (B, X, Y, Z, C), nearest neighbour."""
        bsz, hx, hy, hz, c = x_half.shape
        x = x_half[:, :, None, :, None, :, None, :].expand(bsz, hx, 2, hy, 2, hz, 2, c)
        return x.reshape(bsz, 2 * hx, 2 * hy, 2 * hz, c)

    def upsample_prediction(self, p: torch.Tensor, radius=None) -> torch.Tensor:
        """Sparse up-sampling u(P_{s+1}) -> U_s (paper eq. 6).

        Args:
            p: (B, X/2, Y/2, Z/2, 6) coarser prediction (channel-last).

        Returns:
            (B, X, Y, Z, 6): vertex offsets in the child cells' frames, edge probabilities,
            zeros under non-surface coarse cells.
        """
        bsz, hx, hy, hz, _ = p.shape
        q = torch.sigmoid(p[..., 3:])
        # (B, 3, hx+1, hy+1, hz+1): the far corners of border cells replicate the border
        q_pad = replicate_pad(q.permute(0, 4, 1, 2, 3), (0, 0, 0), (1, 1, 1))
        corners = torch.stack([q_pad[:, :, dx:dx + hx, dy:dy + hy, dz:dz + hz]
                               for dx, dy, dz in _CORNER_TUPLES], dim=-1)
        # (B, hx, hy, hz, 8, 3)
        mask = cell_surface(corners.permute(0, 2, 3, 4, 5, 1))
        mask[:, -1] = False  # cells need their far corner inside the lattice
        mask[:, :, -1] = False
        mask[:, :, :, -1] = False
        # child (dx, dy, dz) of each coarse cell, broadcast over (B, hx, 2, hy, 2, hz, 2, 3)
        child = CELL_CORNERS.to(p.device).reshape(1, 1, 2, 1, 2, 1, 2, 3)
        out = child_prediction(p[:, :, None, :, None, :, None, :],
                               mask[:, :, None, :, None, :, None], child)
        return out.reshape(bsz, 2 * hx, 2 * hy, 2 * hz, 6)

