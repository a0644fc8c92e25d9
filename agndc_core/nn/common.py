"""Geometry shared by the dense and the band evaluation of the network.

The network is written once (``gdfem.py`` ... ``crpm.py``) against a small set of *spatial* ops
(``DenseOps`` in ``dense_ops.py``, ``BandOps`` in ``band_ops.py``). Features are channel-last in
both: ``(B, X, Y, Z, C)`` dense, ``(R, C)`` rows in a band, so every point-wise layer
(``nn.Linear``, activations, concatenation) is the same code. What the two ops classes share is
defined here (or in ``layout.py``, which the numpy runtime reads too):
where a snake's taps fall, which lattice corners a cell's 12 edges leave from, and how a coarse
prediction is re-expressed in its children's frames.

Out-of-grid positions always read the nearest grid point ("replicate" padding): the lattice
border is empty space, so this is what an infinite empty surrounding would give.
"""

from __future__ import annotations

import torch

from ..grid import CELL_EDGES
from ..surfacenets import CENTRE
from . import layout
from .layout import CELL_EDGE_CORNERS, lateral_axes  # noqa: F401  (re-exported)

#: (8, 3) the corners {0,1}^3 of a cell, index = 4 dx + 2 dy + dz (``layout.CELL_CORNERS``)
CELL_CORNERS = torch.from_numpy(layout.CELL_CORNERS)


def cube_offsets(k: int) -> torch.Tensor:
    """(k^3, 3) int64 neighbour offsets of a k x k x k kernel, in ``nn.Conv3d`` weight order."""
    return torch.from_numpy(layout.cube_offsets(k))


def snake_offsets(delta: torch.Tensor, scope: float) -> torch.Tensor:
    """Per-tap drifts -> cumulative lateral offsets of a snake (DSCNet).

    Args:
        delta: (..., 2, K) raw offsets from the offset predictor (any real).
        scope: the extend scope; each tap drifts at most ``scope`` from its predecessor.

    Returns:
        (..., 2, K) offsets: the centre tap stays at 0, tap c +- i sits at the sum of the
        bounded drifts of taps c +- 1 .. c +- i, so the kernel bends like a snake.
    """
    k = delta.shape[-1]
    c = k // 2
    step = torch.tanh(delta) * scope
    up = torch.cumsum(step[..., c + 1:], dim=-1)
    down = torch.cumsum(step[..., :c].flip(-1), dim=-1).flip(-1)
    return torch.cat([down, torch.zeros_like(step[..., c:c + 1]), up], dim=-1)


def snake_corners(coords: torch.Tensor, offsets: torch.Tensor, axis: int):
    """Integer corners and bilinear weights of every tap of a snake.

    Taps along ``axis`` stay on lattice points (tap t at ``t - K // 2``), so each tap
    interpolates only across the two lateral axes: 4 corners.

    Args:
        coords: (N, 3) int64 lattice points the snakes are centred on.
        offsets: (N, 2, K) float cumulative lateral offsets (``snake_offsets``).

    Returns:
        corners (N, K, 4, 3) int64 (unclamped) and weights (N, K, 4) float.
    """
    n, _, k = offsets.shape
    lat_b, lat_c = lateral_axes(axis)
    base = offsets.floor()
    frac = offsets - base  # (N, 2, K), carries the gradient
    pos = coords[:, None, :].expand(n, k, 3).clone()
    pos[:, :, axis] += torch.arange(k, device=coords.device) - k // 2
    pos[:, :, lat_b] += base[:, 0].long()
    pos[:, :, lat_c] += base[:, 1].long()
    corner = torch.from_numpy(layout.SNAKE_CORNERS).to(coords.device)
    # (N, K, 4, 3)
    corners = pos[:, :, None, :].expand(n, k, 4, 3).clone()
    corners[..., lat_b] += corner[:, 0]
    corners[..., lat_c] += corner[:, 1]
    fb, fc = frac[:, 0, :, None], frac[:, 1, :, None]  # (N, K, 1)
    cb, cc = corner[:, 0].to(offsets.dtype), corner[:, 1].to(offsets.dtype)
    weights = (cb * fb + (1 - cb) * (1 - fb)) * (cc * fc + (1 - cc) * (1 - fc))  # (N, K, 4)
    return corners, weights


def cell_surface(q_corners: torch.Tensor) -> torch.Tensor:
    """Surface cells of a coarse prediction: any of the cell's 12 edges has probability > 0.5.

    Args:
        q_corners: (..., 8, 3) edge probabilities at the cell's 8 corners (CELL_CORNERS order).

    Returns:
        (...) bool.
    """
    # basic indexing corner by corner, not a list index: the same maxima, and a step that
    # torch.compile's inductor lowers (it fails on the list index in a compiled training step)
    best = [torch.stack([q_corners[..., i, a] for i in idx], -1).amax(-1)
            for a, idx in enumerate(CELL_EDGE_CORNERS)]
    return torch.stack(best, -1).amax(-1) > 0.5


def child_prediction(p: torch.Tensor, mask: torch.Tensor, child: torch.Tensor) -> torch.Tensor:
    """Re-express a coarse cell's prediction in one of its 8 child cells (sparse up-sampling).

    The coarse vertex at offset ``o`` of coarse cell I lies at fine lattice coordinate
    ``2 (I + o) + 0.5``; child cell ``2 I + c`` sees it at offset ``2 o + 0.5 - c``. Edge logits
    become probabilities; children of non-surface coarse cells are all zero (paper eq. 6).

    Args:
        p: (..., 6) coarse prediction (vertex offsets, edge logits).
        mask: (...) bool surface flag of the coarse cell.
        child: (..., 3) the child's index c in {0, 1}^3.

    Returns:
        (..., 6) float.
    """
    vertex = 2.0 * p[..., :3] + 0.5 - child.to(p.dtype)
    out = torch.cat([vertex, torch.sigmoid(p[..., 3:]).expand(vertex.shape)], dim=-1)
    return out * mask[..., None].to(p.dtype)


@torch.no_grad()
def surface_nets_offsets(occupancy: torch.Tensor) -> torch.Tensor:
    """Surface nets vertex of every cell as an offset from its min corner: the networks' prior,
    batched and on any device (``surfacenets.surface_nets_lattice`` is the same in numpy).

    Args:
        occupancy: (..., X, Y, Z) bool or 0/1 float lattice (any leading batch dims).

    Returns:
        (..., X, Y, Z, 3) float32 offsets in [0, 1]; ``CENTRE`` for cells with no crossed edge
        and for the last layer of cells along each axis (they lack their far corner).
    """
    g = occupancy.to(torch.float32)
    dims = g.shape[-3:]
    n_cells = [max(n - 1, 0) for n in dims]
    lead = g.shape[:-3]
    total = g.new_zeros(*lead, *n_cells, 3)
    count = g.new_zeros(*lead, *n_cells)
    # (..., X-1, Y, Z) etc.: 1 where the edge from p along +axis joins inside and outside
    crossed = [(g.narrow(a - 3, 1, dims[a] - 1) != g.narrow(a - 3, 0, dims[a] - 1)).float()
               for a in range(3)]
    for axis, start in CELL_EDGES:
        # cell c's edge leaving point c + start along axis, and its midpoint in the cell
        part = crossed[axis]
        for a in range(3):
            if a != axis:
                part = part.narrow(a - 3, start[a], n_cells[a])
        count += part
        for a in range(3):
            total[..., a] += (0.5 if a == axis else start[a]) * part
    has = count > 0
    offsets = torch.where(has[..., None], total / count.clamp_min(1.0)[..., None],
                          torch.full_like(total, CENTRE))
    # (..., X, Y, Z, 3): the last layer of cells along each axis stays at the centre
    out = g.new_full((*lead, *dims, 3), CENTRE)
    out[..., :n_cells[0], :n_cells[1], :n_cells[2], :] = offsets
    return out
