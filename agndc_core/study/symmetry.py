"""How far a vertex predictor is from respecting the grid's symmetries.

The right vertex of a cell cannot depend on how the grid happens to be oriented or where it
starts: mirroring the grid along an axis (or shifting it by whole voxels) must mirror (shift)
the predicted vertices and change nothing else. Surface nets and marching cubes do this exactly.
A network does it only as far as training (48-fold augmentation, crops at every alignment)
taught it; what is left is noise that shows as faces which are not flat.

``symmetry_errors`` predicts on the lattice and on its mirrored / shifted copies, maps the
predictions back cell by cell and reports the RMS change of the surface cells' vertices in
voxels. ``face_phase_offsets`` says *where* a shift changes a flat face: it moves an axis-aligned
box through every phase of the cascade's 2**levels grid and reports how far the network puts its
two faces from surface nets' (which is exact there: the binary grid cannot say where in the
voxel such a face lies). Measured numbers are in docs/experiments/flat-face-bias.md.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ..grid import crossed_edges, surface_cells

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
        moved = np.asarray(predict(_shifted(lattice, 0, shift, multiple)), dtype=np.float64)
        errors[f"shift x by {shift}"] = _rms(base, moved[shift:shift + lattice.shape[0]], cells)
    return errors


def face_phase_offsets(predict: Predictor, lattice: np.ndarray, axis: int = 2, *,
                       multiple: int = 4, inset: float = 2.0) -> np.ndarray:
    """Offsets of the two faces normal to ``axis`` at every phase of the lattice.

    The lattice holds one axis-aligned box. For each shift k = 0 .. multiple - 1 it is padded by k
    layers in front along ``axis`` (and back to a multiple behind), and the signed distance along
    +axis of each face-interior vertex from the surface nets vertex is averaged over the face.

    Args:
        predict: the vertex predictor under test.
        lattice: (X, Y, Z) bool lattice holding one axis-aligned box.
        axis: the faces' normal axis.
        multiple: side multiple the predictor needs, and the number of phases (2**levels).
        inset: face-interior vertices lie at least this many voxels from the box's other faces.

    Returns:
        (multiple, 2) float: per shift, the mean offset (voxels, along +axis) of the low face and
        of the high face. Zero everywhere for a predictor that respects shifts and mirrors there.
    """
    from ..surfacenets import surface_nets_lattice

    lattice = np.asarray(lattice, dtype=bool)
    out = np.zeros((multiple, 2))
    for shift in range(multiple):
        padded = _shifted(lattice, axis, shift, multiple)
        cells = surface_cells(crossed_edges(padded))
        reference = surface_nets_lattice(padded).astype(np.float64)
        position = np.argwhere(cells) + reference[cells]  # (N, 3) surface nets vertices
        interior = np.ones(len(position), dtype=bool)
        for other in {0, 1, 2} - {axis}:
            lo, hi = position[:, other].min(), position[:, other].max()
            interior &= (position[:, other] > lo + inset) & (position[:, other] < hi - inset)
        predicted = np.asarray(predict(padded), dtype=np.float64)
        offset = predicted[cells][:, axis] - reference[cells][:, axis]
        along = position[:, axis]
        for side, extreme in enumerate((along.min(), along.max())):
            face = interior & np.isclose(along, extreme)
            if not face.any():
                raise ValueError(f"no face-interior vertices on the {'low high'.split()[side]} "
                                 f"face along axis {axis}: is the lattice one box?")
            out[shift, side] = offset[face].mean()
    return out


def _shifted(lattice: np.ndarray, axis: int, shift: int, multiple: int) -> np.ndarray:
    """The lattice moved ``shift`` points along ``axis`` (empty layers in front), with empty
    layers behind to keep that side a multiple of ``multiple``."""
    pad = [(0, 0)] * 3
    pad[axis] = (shift, -(lattice.shape[axis] + shift) % multiple)
    return np.pad(lattice, pad)


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
