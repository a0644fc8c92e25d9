"""binvox files (https://www.patrickmin.com/binvox/binvox.html): an ASCII header, then
run-length-encoded voxels.

Header: ``#binvox 1``, then ``dim``, ``translate``, ``scale`` lines in any order and ``data``.
We accept ``#`` comment lines and trailing ``#`` comments, blank lines and extra whitespace, as
trimesh's reader does (some files in the wild carry them).

Data: (value, count) byte pairs, count 1..255. Voxels are stored with y running fastest, then z,
then x, so the flat array reshapes to ``(dim_x, dim_z, dim_y)``. ``dim`` is read as
``(dim_x, dim_y, dim_z)`` like trimesh does; the binvox tool only writes cubic grids, where the
order of ``dim`` does not matter.

Placement (the binvox spec): the longest grid side spans ``scale`` world units starting at
``translate``, so voxel ``i`` has its centre at ``translate + (i + 0.5) * scale / max(dim)``.
trimesh instead maps the first and last voxel *centres* to ``translate`` and
``translate + scale``; the two differ by at most half a voxel.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import GridError, GridFileError
from ..grid import MAX_VOXELS

MAX_HEADER_LINES = 200  # a header is ~5 lines; stop long before scanning a whole binary file
MAX_RUN = 255  # a count is one byte
#: relative tolerance for "isotropic, axis-aligned" when writing (float noise from affines)
AXIS_ALIGNED_RTOL = 1e-6


def read_binvox(data: bytes, name: str) -> tuple[np.ndarray, np.ndarray]:
    """Parse a whole binvox file.

    Parameters
    ----------
    data : bytes
        The file contents.
    name : str
        File name used in error messages.

    Returns
    -------
    occupancy : (X, Y, Z) bool
    affine : (4, 4) float64, voxel-centre index coordinates -> world.
    """
    header, payload = _parse_header(data, name)
    dims = header["dim"]
    guard_size(dims, name)
    flat = rle_decode(np.frombuffer(payload, dtype=np.uint8), int(np.prod(dims)), name)
    # stored order x, z, y (y fastest) -> (x, y, z)
    occupancy = flat.reshape(dims[0], dims[2], dims[1]).transpose(0, 2, 1)
    voxel = header["scale"] / max(dims)
    affine = np.eye(4)
    affine[:3, :3] *= voxel
    affine[:3, 3] = header["translate"] + 0.5 * voxel
    return np.ascontiguousarray(occupancy), affine


def write_binvox(occupancy: np.ndarray, affine: np.ndarray, name: str) -> bytes:
    """Encode an (X, Y, Z) bool grid; the affine must be axis-aligned with one positive voxel size.

    Raises
    ------
    GridFileError
        For rotated, sheared, flipped or anisotropic affines, which binvox cannot store.
    """
    voxel = _isotropic_voxel_size(affine, name)
    dims = occupancy.shape
    translate = affine[:3, 3] - 0.5 * voxel
    header = (
        "#binvox 1\n"
        f"dim {dims[0]} {dims[1]} {dims[2]}\n"
        f"translate {translate[0]!r} {translate[1]!r} {translate[2]!r}\n"
        f"scale {voxel * max(dims)!r}\n"
        "data\n"
    )
    # (x, y, z) -> stored order x, z, y
    flat = np.ascontiguousarray(occupancy.transpose(0, 2, 1)).ravel()
    return header.encode("ascii") + rle_encode(flat).tobytes()


def rle_decode(pairs_bytes: np.ndarray, n_voxels: int, name: str) -> np.ndarray:
    """(2R,) uint8 (value, count) pairs -> (n_voxels,) bool.

    Bytes after the run that completes the grid are ignored (some writers add a newline).
    """
    pairs = pairs_bytes[: pairs_bytes.size // 2 * 2].reshape(-1, 2)  # (R, 2)
    ends = np.cumsum(pairs[:, 1], dtype=np.int64)  # voxel count after each run
    decoded = int(ends[-1]) if ends.size else 0
    if decoded < n_voxels:
        raise GridFileError(f"{name}: truncated RLE data: {decoded:,} of {n_voxels:,} voxels")
    last = int(np.searchsorted(ends, n_voxels))  # first run that reaches the grid size
    if ends[last] != n_voxels:
        raise GridFileError(
            f"{name}: corrupt RLE data: a run crosses the end of the grid ({n_voxels:,} voxels)"
        )
    return np.repeat(pairs[: last + 1, 0] != 0, pairs[: last + 1, 1])


def rle_encode(flat: np.ndarray) -> np.ndarray:
    """(N,) bool -> (2R,) uint8 (value, count) pairs with every count in 1..255."""
    values = flat.astype(np.uint8)
    starts = np.concatenate([[0], np.flatnonzero(np.diff(values)) + 1])
    lengths = np.diff(np.append(starts, values.size))
    # split runs longer than one byte can count: all pieces are MAX_RUN but the last
    pieces = -(-lengths // MAX_RUN)
    counts = np.full(int(pieces.sum()), MAX_RUN, dtype=np.int64)
    counts[np.cumsum(pieces) - 1] = lengths - MAX_RUN * (pieces - 1)
    pairs = np.stack([np.repeat(values[starts], pieces), counts], axis=1)  # (R, 2)
    return pairs.astype(np.uint8).ravel()


def guard_size(dims, name: str) -> None:
    """Refuse a header-declared grid that is too large *before* allocating it.

    The product is taken in Python ints: a corrupt header's sizes overflow int64 (2**32 cubed
    wraps to 0). Same error and wording as grid.py's ``as_occupancy`` check.
    """
    dims = tuple(int(d) for d in dims)
    count = math.prod(dims)
    if count > MAX_VOXELS:
        raise GridError(
            f"{name}: grid {dims} has {count:,} voxels, more than the {MAX_VOXELS:,} this "
            "remesher handles in memory; downsample it first"
        )


def _parse_header(data: bytes, name: str) -> tuple[dict, bytes]:
    """Split the file into the parsed header {dim, translate, scale} and the RLE payload."""
    if not data.lstrip().startswith(b"#binvox"):
        raise GridFileError(f"{name}: not a binvox file (the first line is not '#binvox 1')")
    header = {"translate": np.zeros(3), "scale": 1.0}
    pos = data.index(b"\n") + 1 if b"\n" in data else len(data)
    for _ in range(MAX_HEADER_LINES):
        end = data.find(b"\n", pos)
        if end < 0:
            break
        line = data[pos:end].split(b"#", 1)[0].decode("ascii", errors="replace").split()
        pos = end + 1
        if not line:
            continue  # blank or comment-only line
        key, values = line[0].lower(), line[1:]
        if key == "data":
            if "dim" not in header:
                raise GridFileError(f"{name}: binvox header has no 'dim' line")
            return header, data[pos:]
        if key in ("dim", "translate", "scale"):
            header[key] = _header_values(key, values, name)
    raise GridFileError(f"{name}: binvox header ends without a 'data' line (file truncated?)")


def _header_values(key: str, values: list[str], name: str):
    """Convert one header line's values; every problem becomes a GridFileError."""
    expected = 1 if key == "scale" else 3
    try:
        numbers = [int(v) if key == "dim" else float(v) for v in values]
    except ValueError:
        numbers = []
    if key == "dim" and len(numbers) == 1:
        numbers *= 3  # some old writers give one size for a cube
    # dim values are ints (always finite, maybe too large for a float); the others are floats
    finite = key == "dim" or all(math.isfinite(n) for n in numbers)
    if len(numbers) != expected or not finite:
        raise GridFileError(f"{name}: bad binvox header line '{key} {' '.join(values)}'")
    if key == "dim":
        if min(numbers) < 1:
            raise GridFileError(f"{name}: binvox dim must be positive, got {numbers}")
        return tuple(numbers)
    if key == "scale":
        if numbers[0] <= 0:
            raise GridFileError(f"{name}: binvox scale must be positive, got {numbers[0]}")
        return numbers[0]
    return np.asarray(numbers, dtype=np.float64)


def _isotropic_voxel_size(affine: np.ndarray, name: str) -> float:
    """The one voxel size of an axis-aligned, unflipped, isotropic affine, else GridFileError."""
    linear = affine[:3, :3]
    diagonal = np.diag(linear)
    size = float(np.abs(diagonal).max())
    off_diagonal = linear - np.diag(diagonal)
    rotated = np.abs(off_diagonal).max() > AXIS_ALIGNED_RTOL * size
    if rotated or np.any(diagonal <= 0) or np.ptp(diagonal) > AXIS_ALIGNED_RTOL * size:
        raise GridFileError(
            f"{name}: binvox can only store axis-aligned grids with the same positive voxel size "
            f"on every axis, got voxel sizes {diagonal.round(6).tolist()}"
            f"{' and a rotation/shear' if rotated else ''}; save as .npz or .nii instead"
        )
    return float(diagonal.mean())
