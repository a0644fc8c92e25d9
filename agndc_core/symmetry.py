"""How far a vertex predictor is from respecting the grid's symmetries.

The right vertex of a cell cannot depend on how the grid happens to be oriented or where it
starts: mirroring the grid along an axis (or shifting it by whole voxels) must mirror (shift)
the predicted vertices and change nothing else. Surface nets and marching cubes do this exactly.
A network does it only as far as training (48-fold augmentation, crops at every alignment)
taught it; what is left is noise that shows as faces which are not flat.

``symmetry_errors`` predicts on the lattice and on its mirrored / shifted copies, maps the
predictions back cell by cell and reports the RMS change of the surface cells' vertices in
voxels. Measured numbers are in docs/training.md.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from .labels import crossed_edges, surface_cells

#: vertex predictor: (X, Y, Z) bool lattice -> (X, Y, Z, 3) offsets of each cell's vertex from its
#: min corner, in voxels (``surface_nets_lattice``, ``inference.predict_lattice``'s vertices)
Predictor = Callable[[np.ndarray], np.ndarray]


def symmetry_errors(predict: Predictor, lattice: np.ndarray, *, multiple: int = 4,
                    shifts=(1, 2, 3)) -> dict[str, float]:
    """RMS change (voxels) of the surface cells' vertices under each mirror and shift.

    Args:
        predict: the vertex predictor under test.
        lattice: (X, Y, Z) bool lattice (``grid.pad_to_lattice``), sides multiples of ``multiple``.
        multiple: side multiple the predictor needs (2**levels of the cascade); shifted copies are
            padded to keep it.
        shifts: whole-voxel shifts along x to test (a cascade pools 2x2x2 blocks, so shifts that
            are not multiples of 2**levels change what its coarse scales see).

    Returns:
        {"mirror x", "mirror y", "mirror z", "shift x by k" ...: RMS in voxels}.
    """
    lattice = np.asarray(lattice, dtype=bool)
    if any(n % multiple for n in lattice.shape):
        raise ValueError(f"lattice sides {lattice.shape} must be multiples of {multiple}")
    cells = surface_cells(crossed_edges(lattice))  # (X, Y, Z) bool: the vertices that are used
    base = np.asarray(predict(lattice), dtype=np.float64)
    errors = {}
    for axis in range(3):
        mirrored = np.asarray(predict(np.flip(lattice, axis)), dtype=np.float64)
        errors[f"mirror {'xyz'[axis]}"] = _rms(base, _unmirror(mirrored, axis), cells)
    for shift in shifts:
        padded = np.pad(lattice, [(shift, multiple - shift % multiple if shift % multiple else 0),
                                  (0, 0), (0, 0)])
        moved = np.asarray(predict(padded), dtype=np.float64)
        errors[f"shift x by {shift}"] = _rms(base, moved[shift:shift + lattice.shape[0]], cells)
    return errors


def _unmirror(offsets: np.ndarray, axis: int) -> np.ndarray:
    """Predictions on a lattice mirrored along ``axis`` -> the original lattice's cells.

    Cell c spans points c and c + 1; mirrored, they are points D-1-c and D-2-c, i.e. cell D-2-c,
    and an offset o from that cell's min corner is 1 - o from the original's. The last layer of
    cells (no far corner) has no partner and keeps NaN.
    """
    n = offsets.shape[axis]
    out = np.full_like(offsets, np.nan)
    src = [slice(None)] * 3
    dst = [slice(None)] * 3
    src[axis], dst[axis] = slice(n - 2, None, -1), slice(0, n - 1)
    out[tuple(dst)] = offsets[tuple(src)]
    out[..., axis] = 1.0 - out[..., axis]
    return out


def _rms(a: np.ndarray, b: np.ndarray, cells: np.ndarray) -> float:
    diff = (a - b)[cells]  # (N, 3)
    return float(np.sqrt(np.mean(np.sum(diff**2, axis=-1)))) if len(diff) else 0.0
