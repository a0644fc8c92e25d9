"""MagicaVoxel ``.vox`` files (spec: github.com/ephtracy/voxel-model,
``MagicaVoxel-file-format-vox.txt``).

Layout: ``"VOX "``, int32 version, then one ``MAIN`` chunk whose children hold, per model, a
``SIZE`` chunk (int32 x, y, z) followed by an ``XYZI`` chunk (int32 n, then n x 4 uint8
x, y, z, colour index). A chunk is: 4-byte id, int32 content size, int32 children size, content,
children. The palette chunk ``RGBA`` (256 x 4 uint8; its entry ``k`` is the colour of index
``k + 1``) is read by ``read_vox_colors``, which falls back to MagicaVoxel's default palette
(``vox_palette.py``) when it is absent; other chunks (``PACK``, materials, scene graph) are
skipped.

Every voxel listed in ``XYZI`` is occupied, whatever its colour; colour index 0 (which MagicaVoxel
never writes and treats as empty) is empty. The scene-graph placement of models is ignored:
grids load with voxel size 1 and origin 0. Coordinates are uint8, so an axis holds at most 256.
"""

from __future__ import annotations

import struct

import numpy as np

from ..errors import GridFileError
from .binvox import guard_size
from .vox_palette import default_palette

MAGIC = b"VOX "
VERSION = 150
MAX_DIM = 256  # coordinates are stored as one byte each
CHUNK_HEADER = struct.Struct("<4sii")  # id, content size, children size


def read_vox(data: bytes, name: str, model_index: int = 0) -> np.ndarray:
    """Parse a .vox file and return model ``model_index`` as (X, Y, Z) bool occupancy.

    Raises
    ------
    GridFileError
        Not a .vox file, truncated or inconsistent chunks, or no such model.
    """
    return read_vox_colors(data, name, model_index)[0] != 0


def read_vox_colors(data: bytes, name: str, model_index: int = 0) -> tuple[np.ndarray,
                                                                           np.ndarray]:
    """Model ``model_index`` of a .vox file with its colours.

    Returns
    -------
    indices : (X, Y, Z) uint8
        The palette index of each voxel, 0 where it is empty (occupancy is ``indices != 0``).
    palette : (256, 4) uint8
        RGBA of each index: the file's ``RGBA`` chunk, else MagicaVoxel's default palette.

    Raises GridFileError as ``read_vox``.
    """
    models, palette = _model_table(data, name)
    if not 0 <= model_index < len(models):
        raise GridFileError(
            f"{name}: model_index {model_index} is out of range: the file holds "
            f"{len(models)} model{'s' if len(models) != 1 else ''} (0..{len(models) - 1})"
        )
    size, offset, length = models[model_index]
    return _voxels(data, size, offset, length, name), palette


def count_vox_models(data: bytes, name: str) -> int:
    """Number of models in a .vox file (GridFileError as ``read_vox`` for a bad file)."""
    return len(_model_table(data, name)[0])


def _model_table(data: bytes, name: str) -> tuple[list[tuple[tuple, int, int]], np.ndarray]:
    """The checked header, the (non-empty) model list of a .vox file (see ``_models``) and its
    (256, 4) uint8 palette."""
    if len(data) < 8 or data[:4] != MAGIC:
        raise GridFileError(f"{name}: not a MagicaVoxel file (it does not start with 'VOX ')")
    chunk_id, content, children, start = _chunk_at(data, 8, len(data), name)
    if chunk_id != b"MAIN":
        raise GridFileError(f"{name}: .vox file has no MAIN chunk (found {chunk_id!r})")
    models, palette = _models(data, start + content, start + content + children, name)
    if not models:
        raise GridFileError(f"{name}: .vox file holds no voxel model (no XYZI chunk)")
    return models, palette


def write_vox(occupancy: np.ndarray, name: str, *, colors: np.ndarray | None = None,
              palette: np.ndarray | None = None) -> bytes:
    """Encode an (X, Y, Z) bool grid as a single-model .vox.

    ``colors`` (X, Y, Z) uint8 gives each occupied voxel its palette index (an occupied voxel
    with index 0 gets 1); without it every voxel has index 1. ``palette`` (256, 4) uint8 RGBA
    (row ``i`` = index ``i``) is written as the ``RGBA`` chunk; without it there is none and
    readers use MagicaVoxel's default palette.
    """
    if max(occupancy.shape) > MAX_DIM:
        raise GridFileError(
            f"{name}: .vox holds at most {MAX_DIM} voxels per axis, the grid is {occupancy.shape}; "
            "save as .npz, .binvox or .nii instead"
        )
    xyz = np.argwhere(occupancy)  # (N, 3)
    index = np.ones(len(xyz), dtype=np.uint8)  # (N,)
    if colors is not None:
        index = np.maximum(np.asarray(colors, dtype=np.uint8)[tuple(xyz.T)], 1)
    xyzi = np.concatenate([xyz.astype(np.uint8), index[:, None]], axis=1)  # (N, 4)
    size = _chunk(b"SIZE", struct.pack("<3i", *occupancy.shape))
    voxels = _chunk(b"XYZI", struct.pack("<i", len(xyz)) + xyzi.tobytes())
    children = size + voxels
    if palette is not None:
        rgba = np.zeros((256, 4), dtype=np.uint8)
        rgba[:255] = np.asarray(palette, dtype=np.uint8).reshape(256, 4)[1:]  # entry k: k + 1
        children += _chunk(b"RGBA", rgba.tobytes())
    return MAGIC + struct.pack("<i", VERSION) + _chunk(b"MAIN", b"", children)


def _chunk(chunk_id: bytes, content: bytes, children: bytes = b"") -> bytes:
    return CHUNK_HEADER.pack(chunk_id, len(content), len(children)) + content + children


def _chunk_at(data: bytes, pos: int, end: int, name: str) -> tuple[bytes, int, int, int]:
    """(id, content size, children size, content start) of the chunk at ``pos``, bounds-checked."""
    if pos + CHUNK_HEADER.size > end:
        raise GridFileError(f"{name}: truncated .vox file (chunk header at byte {pos:,})")
    chunk_id, content, children = CHUNK_HEADER.unpack_from(data, pos)
    start = pos + CHUNK_HEADER.size
    if content < 0 or children < 0 or start + content + children > end:
        raise GridFileError(
            f"{name}: truncated or corrupt .vox file: chunk {chunk_id!r} at byte {pos:,} claims "
            f"{content + children:,} bytes, {max(end - start, 0):,} left"
        )
    return chunk_id, content, children, start


def _models(data: bytes, pos: int, end: int,
            name: str) -> tuple[list[tuple[tuple, int, int]], np.ndarray]:
    """Walk MAIN's children: [(size (3,), XYZI content start, XYZI content length)] per model,
    and the (256, 4) uint8 palette (``RGBA``, else the default)."""
    models, size, palette = [], None, default_palette()
    while pos < end:  # one step per chunk, never per voxel
        chunk_id, content, children, start = _chunk_at(data, pos, end, name)
        if chunk_id == b"SIZE":
            if content < 12:
                raise GridFileError(f"{name}: corrupt .vox SIZE chunk ({content} bytes)")
            size = struct.unpack_from("<3i", data, start)
            if min(size) < 1:
                raise GridFileError(f"{name}: .vox model size must be positive, got {size}")
        elif chunk_id == b"XYZI":
            if size is None:
                raise GridFileError(f"{name}: corrupt .vox file: XYZI chunk without a SIZE chunk")
            models.append((size, start, content))
            size = None
        elif chunk_id == b"RGBA":
            if content < 4 * 256:
                raise GridFileError(f"{name}: corrupt .vox RGBA chunk ({content} bytes, "
                                    "1,024 expected)")
            rgba = np.frombuffer(data, dtype=np.uint8, count=4 * 256, offset=start)
            palette = default_palette()
            palette[1:] = rgba.reshape(256, 4)[:255]  # entry k is the colour of index k + 1
        pos = start + content + children
    return models, palette


def _voxels(data: bytes, size: tuple, offset: int, length: int, name: str) -> np.ndarray:
    """Decode one XYZI chunk's content into an (X, Y, Z) uint8 colour-index grid of ``size``
    (0 = empty)."""
    if length < 4:
        raise GridFileError(f"{name}: truncated .vox XYZI chunk (no voxel count)")
    count = struct.unpack_from("<i", data, offset)[0]
    if count < 0 or 4 + 4 * count > length:
        raise GridFileError(
            f"{name}: truncated .vox XYZI chunk: {max(length - 4, 0) // 4:,} of {count:,} voxels"
        )
    guard_size(size, name)
    xyzi = np.frombuffer(data, dtype=np.uint8, count=4 * count, offset=offset + 4).reshape(-1, 4)
    xyzi = xyzi[xyzi[:, 3] != 0]  # (N, 4), colour 0 = empty
    xyz = xyzi[:, :3].astype(np.int64)  # (N, 3)
    if np.any(xyz >= np.asarray(size)):
        raise GridFileError(f"{name}: corrupt .vox model: voxels lie outside its size {size}")
    indices = np.zeros(size, dtype=np.uint8)
    indices[xyz[:, 0], xyz[:, 1], xyz[:, 2]] = xyzi[:, 3]
    return indices
