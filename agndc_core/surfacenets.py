"""Surface nets vertices: each surface cell's dual vertex at the mean of its crossed-edge midpoints.

The classical no-learning dual method (Gibson 1998, without the relaxation). It is

* a method of its own (``remesh(..., method="surfacenets")``), the baseline a network has to beat;
* the **prior** of the learned methods: their finest scale predicts a correction to this vertex
  (``vertex = surface_nets + network``), so an untrained network already gives surface nets and
  every gradient step works on what binary input cannot tell by itself.

Coordinates follow grid.py: cell ``c`` spans lattice points ``c .. c + 1`` and its vertex is
``c + offset``. ``surface_nets_offsets_naive`` is the slow, obviously correct reference.
"""

from __future__ import annotations

import itertools

import numpy as np
import torch

from .grid import CELL_EDGES

#: offset of a cell without any crossed edge (its centre): such cells are never contoured, and
#: the prior's *delta* (offset - centre) is zero there, which keeps band inference's far field
#: untouched
CENTRE = 0.5


@torch.no_grad()
def surface_nets_offsets(occupancy: torch.Tensor) -> torch.Tensor:
    """Surface nets vertex of every cell as an offset from its min corner.

    Args:
        occupancy: (..., X, Y, Z) bool or 0/1 float lattice (any leading batch dims, any device).

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


def surface_nets_lattice(lattice: np.ndarray) -> np.ndarray:
    """numpy convenience: (X, Y, Z) bool lattice -> (X, Y, Z, 3) float32 offsets."""
    return surface_nets_offsets(torch.from_numpy(np.ascontiguousarray(lattice))).numpy()


def surface_nets_offsets_naive(lattice: np.ndarray) -> np.ndarray:
    """Cell-by-cell reference of ``surface_nets_offsets`` for one (X, Y, Z) lattice (slow)."""
    lattice = np.asarray(lattice, dtype=bool)
    out = np.full(lattice.shape + (3,), CENTRE, dtype=np.float64)
    for cell in itertools.product(*(range(n - 1) for n in lattice.shape)):
        midpoints = []
        for corner in itertools.product((0, 1), repeat=3):
            for axis in range(3):
                if corner[axis]:
                    continue  # each edge once: from its low end point
                a = tuple(c + d for c, d in zip(cell, corner))
                b = list(a)
                b[axis] += 1
                if lattice[a] != lattice[tuple(b)]:
                    mid = np.array(corner, dtype=np.float64)
                    mid[axis] = 0.5
                    midpoints.append(mid)
        if midpoints:
            out[cell] = np.mean(midpoints, axis=0)
    return out.astype(np.float32)
