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

from .grid import CELL_EDGES

#: offset of a cell without any crossed edge (its centre): such cells are never contoured, and
#: the prior's *delta* (offset - centre) is zero there, which keeps band inference's far field
#: untouched
CENTRE = 0.5


def surface_nets_lattice(lattice: np.ndarray) -> np.ndarray:
    """(X, Y, Z) bool lattice -> (X, Y, Z, 3) float32 surface nets offsets (numpy; the same
    sums in the same order as ``nn.common.surface_nets_offsets``, the batched torch version the
    networks' prior uses in training)."""
    g = np.asarray(lattice).astype(np.float32)
    dims = g.shape
    n_cells = [max(n - 1, 0) for n in dims]
    total = np.zeros((*n_cells, 3), dtype=np.float32)
    count = np.zeros(n_cells, dtype=np.float32)
    # (X-1, Y, Z) etc.: 1 where the edge from p along +axis joins inside and outside
    crossed = [(np.diff(g, axis=a) != 0).astype(np.float32) for a in range(3)]
    for axis, start in CELL_EDGES:
        part = crossed[axis][tuple(slice(0, n_cells[a]) if a == axis
                                   else slice(start[a], start[a] + n_cells[a])
                                   for a in range(3))]
        count += part
        for a in range(3):
            total[..., a] += np.float32(0.5 if a == axis else start[a]) * part
    has = count > 0
    offsets = np.where(has[..., None], total / np.maximum(count, 1.0)[..., None],
                       np.float32(CENTRE)).astype(np.float32)
    out = np.full((*dims, 3), CENTRE, dtype=np.float32)
    out[:n_cells[0], :n_cells[1], :n_cells[2]] = offsets
    return out


def surface_nets_cells(lattice: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """``surface_nets_lattice`` at some cells only: (C,) flat cell ids into the lattice's shape
    (cells, not the last layer of points along any axis) -> (C, 3) float32 offsets, the same
    sums in the same order (so the same values to the bit). A check that needs the vertices of
    the contoured cells alone reads 8 corners per cell instead of filling a dense field (200 MB
    and seconds at 256³)."""
    flat = np.asarray(lattice, dtype=bool).reshape(-1)
    cells = np.asarray(cells, dtype=np.int64)
    strides = np.array([lattice.shape[1] * lattice.shape[2], lattice.shape[2], 1])
    total = np.zeros((len(cells), 3), dtype=np.float32)
    count = np.zeros(len(cells), dtype=np.float32)
    for axis, start in CELL_EDGES:
        low = cells + int(np.dot(start, strides))
        part = (flat[low] != flat[low + strides[axis]]).astype(np.float32)
        count += part
        for a in range(3):
            total[:, a] += np.float32(0.5 if a == axis else start[a]) * part
    has = count > 0
    return np.where(has[:, None], total / np.maximum(count, 1.0)[:, None],
                    np.float32(CENTRE)).astype(np.float32)


def surface_nets_offsets_naive(lattice: np.ndarray) -> np.ndarray:
    """Cell-by-cell reference of ``surface_nets_lattice`` for one (X, Y, Z) lattice (slow)."""
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
