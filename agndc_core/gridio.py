"""Reading and writing voxel grids and meshes: one entry point per direction, chosen by extension.

Grids (``load_grid`` / ``save_grid``):

* ``.npy``: the occupancy array only (bool, or numeric 0/1); loads with voxel size 1, origin 0.
* ``.npz``: the array named ``occupancy`` (else ``grid``, ``voxels``, ``data``, else the only 3-D
  array) plus, when present, ``affine`` (4x4) or ``voxel_size`` + ``origin``.
* ``.binvox`` and MagicaVoxel ``.vox``: see ``agndc_core.formats``.
* ``.nii`` / ``.nii.gz`` (NIfTI, via nibabel): occupancy is ``data > 0``, so 0/1 masks and label
  volumes (every non-zero label is solid, negative labels are empty) both work; continuous float
  volumes are refused (threshold them first). The header's affine is kept, so meshes come out in
  world units (nibabel's affine maps voxel indices to world exactly like ``VoxelGrid.affine``).
  NIfTI stores the affine in float32, so a saved affine comes back to about 1e-7 relative.
  A label volume read so is one mask, its labels merged: ``labelmaps.MergedLabelsWarning`` says
  so, and ``labelmaps.py`` meshes each label on its own (``load_grid_values`` reads the values).

Meshes (``load_mesh`` / ``save_mesh``) go through trimesh.

Every file is written to a temporary name beside its target (``temp_path``) and renamed into
place, so a crash, Ctrl-C or kill never leaves a partial grid or mesh under the target's name.

Every missing, corrupt, truncated or unsupported file raises ``GridFileError`` with a message
that names the file; grid *content* problems (non-binary values, wrong shape, too large) are
``GridError`` from ``grid.py``, and unusable meshes are ``MeshError``. No other exception type
escapes: what a parser raises on corrupt bytes is wrapped (``_reading``), and sizes a header
declares are checked against ``grid.MAX_VOXELS`` and against the bytes the file holds before
anything is allocated. ``tests/core/test_fuzz_readers.py`` checks this on mutated files.
"""

from __future__ import annotations

import gzip
import io
import math
import os
import warnings
import zipfile
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from .errors import AGNDCError, GridError, GridFileError
from .formats.binvox import guard_size, read_binvox, write_binvox
from .formats.vox import count_vox_models, read_vox_colors, write_vox
from .grid import MAX_VOXELS, VoxelGrid
from .voxelize import check_mesh

GRID_EXTENSIONS = (".npy", ".npz", ".binvox", ".vox", ".nii", ".nii.gz")
#: grid formats that can hold a label map, one integer value per structure
#: (``load_grid_values``, ``labelmaps.py``)
LABEL_EXTENSIONS = (".npy", ".npz", ".nii", ".nii.gz")
#: meshes ``load_mesh`` reads (trimesh's loaders that need no optional dependency)
MESH_EXTENSIONS = (".obj", ".ply", ".stl", ".off", ".glb", ".gltf")
#: meshes ``save_mesh`` writes
MESH_SAVE_EXTENSIONS = (".obj", ".ply", ".stl", ".glb")
#: array names tried in order when reading an .npz
NPZ_ARRAY_NAMES = ("occupancy", "grid", "voxels", "data")
NPY_MAGIC = b"\x93NUMPY"
ZIP_MAGIC = b"PK\x03\x04"
#: marks a file being written (``temp_path``): ``name.tmp-<pid>.<ext>``, renamed when complete
TEMP_MARK = ".tmp-"
#: bytes read at a time when measuring a compressed NIfTI's payload
_CHUNK = 1 << 20


def is_grid_path(path) -> bool:
    """True when ``path`` has a grid extension (``.nii.gz`` included), case-insensitive."""
    return _extension(path, GRID_EXTENSIONS) is not None


def is_mesh_path(path) -> bool:
    """True when ``path`` has a mesh extension that ``load_mesh`` reads, case-insensitive."""
    return _extension(path, MESH_EXTENSIONS) is not None


def load_grid(path, *, model_index: int = 0) -> VoxelGrid:
    """Load a voxel grid file.

    Parameters
    ----------
    path : str or Path
        A file with one of ``GRID_EXTENSIONS``.
    model_index : int
        Which model of a multi-model MagicaVoxel ``.vox`` file to load; ignored otherwise.

    Returns
    -------
    VoxelGrid
        (X, Y, Z) bool occupancy and its 4x4 affine; ``source`` is the file name. Empty grids load.
        A ``.vox`` grid also carries its voxels' palette indices and palette (``colors``).

    Raises
    ------
    GridFileError
        Missing, unreadable, corrupt, truncated or unsupported file.
    GridError
        The file is fine but its array is not a usable binary 3-D grid.
    """
    path = Path(path)
    ext = _require_extension(path, GRID_EXTENSIONS, "grid")
    _require_file(path)
    name = path.name
    if ext == ".npy":
        return _binary_grid(_read_npy(path), np.eye(4), name)
    if ext == ".npz":
        return _read_npz(path)
    if ext == ".binvox":
        occupancy, affine = read_binvox(_read_bytes(path), name)
        return VoxelGrid(occupancy, affine, source=name)
    if ext == ".vox":
        from .colors import VoxelColors

        indices, palette = read_vox_colors(_read_bytes(path), name, model_index)
        return VoxelGrid(indices != 0, source=name, colors=VoxelColors(indices, palette))
    return _read_nifti(path)


def load_grid_values(path) -> tuple[np.ndarray, np.ndarray]:
    """The voxel values of a grid file that can hold a label map (``LABEL_EXTENSIONS``), as
    stored, before they become occupancy, and the file's placement.

    Returns
    -------
    values : (X, Y, Z) array of the file's dtype
    affine : (4, 4) float64 index -> world (identity for ``.npy``), as ``load_grid`` reads it

    Raises GridFileError like ``load_grid`` (other formats: one that says which hold labels).
    """
    path = Path(path)
    ext = _require_extension(path, GRID_EXTENSIONS, "grid")
    if ext not in LABEL_EXTENSIONS:
        raise GridFileError(f"{path.name}: {ext} files hold one solid, not a label map; label "
                            f"maps are read from {', '.join(LABEL_EXTENSIONS)}")
    _require_file(path)
    if ext == ".npy":
        return _read_npy(path), np.eye(4)
    if ext == ".npz":
        values, placement = _npz_values(path)
        return values, _npz_affine(placement, path.name)
    return _nifti_values(path)


def _npz_affine(placement: dict, name: str) -> np.ndarray:
    """(4, 4) affine of an .npz archive's placement arrays (identity when it has none), checked
    as ``VoxelGrid`` checks it (on a one-voxel stand-in: the values are checked apart)."""
    # placement arrays of the wrong shape or type: numpy's error, named and wrapped
    with _reading(name, "unusable affine, voxel_size or origin array"):
        stand_in = np.zeros((1, 1, 1), dtype=bool)
        if "affine" in placement:
            return VoxelGrid(stand_in, placement["affine"], source=name).affine
        if "voxel_size" in placement and "origin" in placement:
            return VoxelGrid.from_spacing(stand_in, placement["voxel_size"],
                                          placement["origin"], source=name).affine
    return np.eye(4)


def grid_model_count(path) -> int:
    """How many grids a file holds: the models of a MagicaVoxel ``.vox``, 1 for other formats.

    Raises GridFileError like ``load_grid`` for a missing, unreadable or corrupt ``.vox``.
    """
    path = Path(path)
    ext = _require_extension(path, GRID_EXTENSIONS, "grid")
    _require_file(path)
    if ext != ".vox":
        return 1
    return count_vox_models(_read_bytes(path), path.name)


def save_grid(grid: VoxelGrid, path) -> None:
    """Write ``grid`` to ``path``, in the format its extension names.

    ``.npy`` and ``.vox`` store the occupancy only (placement is lost; ``.vox`` keeps the grid's
    ``colors`` when it has them); ``.npz`` and NIfTI keep the full affine; ``.binvox`` needs an
    axis-aligned isotropic affine and ``.vox`` at most 256 voxels per axis, otherwise a
    GridFileError says so.
    """
    path = Path(path)
    ext = _require_extension(path, GRID_EXTENSIONS, "grid")
    occupancy, name = grid.occupancy, path.name
    if ext in (".npy", ".npz"):
        buffer = io.BytesIO()
        if ext == ".npy":
            np.save(buffer, occupancy)
        else:
            np.savez_compressed(buffer, occupancy=occupancy, affine=grid.affine)
        data = buffer.getvalue()
    elif ext == ".binvox":
        data = write_binvox(occupancy, grid.affine, name)
    elif ext == ".vox":
        colors = grid.colors
        data = write_vox(occupancy, name, colors=None if colors is None else colors.indices,
                         palette=None if colors is None else colors.palette)
    else:
        data = _nifti_bytes(grid, gzipped=ext == ".nii.gz")
    _write_bytes(path, data)


def load_mesh(path) -> tuple[np.ndarray, np.ndarray]:
    """Load a triangle mesh; scenes are flattened into one mesh and duplicate vertices merged.

    Returns
    -------
    vertices : (V, 3) float64
    faces : (F, 3) int64

    Raises
    ------
    GridFileError
        Missing, unreadable or unsupported file.
    MeshError
        No faces, non-finite coordinates or zero extent.
    """
    import trimesh

    path = Path(path)
    _require_extension(path, MESH_EXTENSIONS, "mesh")
    _require_file(path)
    if path.suffix.lower() == ".stl":
        _require_stl_layout(path)
    with _reading(path.name, "cannot read the mesh"):
        try:
            loaded = trimesh.load(path, force="mesh", process=False)
        except ModuleNotFoundError as exc:
            if exc.name != "charset_normalizer":
                raise
            # trimesh guesses the encoding of non-UTF-8 text with this optional package
            raise GridFileError(f"{path.name}: cannot read the mesh: its text is not UTF-8 "
                                "(or its binary data is corrupt)") from None
    # check (non-empty, faces in range, finite, (V, 3)) before merging: trimesh's processing
    # would silently drop non-finite vertices; a loader's odd output is still a named error
    with _reading(path.name, "unusable mesh data"):
        vertices = getattr(loaded, "vertices", np.zeros((0, 3)))
        faces = getattr(loaded, "faces", None)
        faces = np.zeros((0, 3), dtype=np.int64) if faces is None else faces
        vertices, faces = check_mesh(vertices, faces, source=path.name)
        mesh = trimesh.Trimesh(vertices, faces, process=False)
        mesh.remove_unreferenced_vertices()
        mesh.merge_vertices()
    return np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64)


def _require_stl_layout(path: Path) -> None:
    """Refuse a .stl that is neither binary STL (84 + 50 n bytes, n read at byte 80) nor ASCII
    STL (text starting with ``solid``). Without this, random bytes decode as an ASCII STL with
    no facets wherever trimesh can guess a text encoding, and read as "a mesh without faces"."""
    size = path.stat().st_size
    with open(path, "rb") as handle:
        head = handle.read(84)
    binary = size >= 84 and size == 84 + 50 * int.from_bytes(head[80:84], "little")
    if not binary and not head.lstrip().lower().startswith(b"solid"):
        raise GridFileError(f"{path.name}: cannot read the mesh: neither a binary STL (its size "
                            "does not match its triangle count) nor an ASCII STL")


def polygon_extensions(colored: bool = False) -> tuple[str, ...]:
    """The mesh outputs ``save_mesh`` writes quads to (a coloured ``.ply`` keeps triangles)."""
    return (".obj",) if colored else (".obj", ".ply")


def save_mesh(vertices, faces, path, *, face_colors=None, palette=None,
              polygons=None) -> None:
    """Write a triangle mesh, keeping the vertex order (no merging or reordering).

    Parameters
    ----------
    vertices : (V, 3) float
    faces : (F, 3) int
    path : str or Path
        ``.obj``, ``.ply``, ``.stl`` or ``.glb``.
    face_colors : (F,) uint8, optional
        Palette index of each face, with ``palette`` (256, 4) uint8 sRGB(A): ``.glb`` gets one
        material per used colour, ``.ply`` face colours (``colors.colored_mesh_bytes``);
        ``.obj`` and ``.stl`` stay plain geometry.
    polygons : quads.QuadMesh, optional
        The same surface as quads and triangles (``RemeshResult.polygons()``): written instead
        of ``faces`` to ``.obj``, and to ``.ply`` without ``face_colors`` (a coloured ``.ply``
        keeps its triangles); ``.stl`` and ``.glb`` hold triangles only and get ``faces``.
    """
    import trimesh

    path = Path(path)
    ext = _require_extension(path, MESH_SAVE_EXTENSIONS, "mesh output")
    vertices = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    if polygons is not None and ext in polygon_extensions(face_colors is not None):
        from .formats.polygons import obj_bytes, ply_bytes

        write = obj_bytes if ext == ".obj" else ply_bytes
        _write_bytes(path, write(vertices, polygons.quads, polygons.triangles))
        return
    data = None
    if face_colors is not None and len(faces):
        from .colors import colored_mesh_bytes

        data = colored_mesh_bytes(vertices, faces, face_colors, palette, ext[1:])
    if data is None:
        data = trimesh.Trimesh(vertices, faces, process=False).export(file_type=ext[1:])
    _write_bytes(path, data.encode("utf-8") if isinstance(data, str) else data)


# --- format readers ---------------------------------------------------------------------------


def _read_npy(path: Path) -> np.ndarray:
    name = path.name
    with _reading(name, "not a readable .npy file"), path.open("rb") as file:
        if file.read(len(ZIP_MAGIC)) == ZIP_MAGIC:  # np.save never writes a zip
            raise GridFileError(f"{name}: this is an .npz archive, not an .npy array")
        file.seek(0)
        return _npy_data(file, path.stat().st_size, _npy_header(file, name), name)


def _read_npz(path: Path) -> VoxelGrid:
    values, placement = _npz_values(path)
    return _binary_grid(values, _npz_affine(placement, path.name), path.name)


def _binary_grid(values: np.ndarray, affine: np.ndarray, name: str) -> VoxelGrid:
    """The grid of an .npy / .npz array; a label map is refused with what to do instead."""

    if isinstance(values, np.ndarray) and values.ndim == 3:
        refuse_label_map(values, name)
    return VoxelGrid(values, affine, source=name)


def _npz_values(path: Path) -> tuple[np.ndarray, dict]:
    """The grid array (see NPZ_ARRAY_NAMES) as stored and its placement arrays (``affine``,
    ``voxel_size``, ``origin``), if the archive stores them.

    Only those arrays are decompressed, one at a time, so memory stays within one grid whatever
    the other members hold.
    """
    name = path.name
    with _reading(name, "not a readable .npz archive"):
        with path.open("rb") as file:
            if file.read(len(NPY_MAGIC)) == NPY_MAGIC:
                raise GridFileError(f"{name}: this is an .npy array, not an .npz archive")
        with zipfile.ZipFile(path) as archive:
            # np.savez writes one <key>.npy member per array
            members = {info.filename[:-4]: info for info in archive.infolist()
                       if info.filename.endswith(".npy")}
            shapes = {key: _npz_member(archive, info, name, header_only=True)[0]
                      for key, info in members.items()}
            wanted = [_npz_occupancy_key(shapes, name)]
            wanted += [key for key in ("affine", "voxel_size", "origin") if key in members]
            arrays = {key: _npz_member(archive, members[key], name) for key in wanted}
    return arrays.pop(wanted[0]), arrays


def _npz_member(archive: zipfile.ZipFile, info: zipfile.ZipInfo, name: str, *,
                header_only: bool = False):
    """One member's array, or only its header ``(shape, fortran_order, dtype)``."""
    label = f"{name}: member {info.filename}"
    with _reading(label, "not a readable .npy array"), archive.open(info) as member:
        header = _npy_header(member, label)
        return header if header_only else _npy_data(member, info.file_size, header, label)


def _npy_header(stream, label: str) -> tuple[tuple, bool, np.dtype]:
    """Parse an .npy header; refuse object arrays and arrays beyond ``MAX_VOXELS`` elements.

    numpy's own ``np.load`` allocates whatever the header claims before it reads the data, and
    its header parser leaks ``TokenError``/``SyntaxError`` (``_reading`` wraps those).
    """
    version = np.lib.format.read_magic(stream)
    if version == (1, 0):
        shape, fortran_order, dtype = np.lib.format.read_array_header_1_0(stream)
    elif version == (2, 0):
        shape, fortran_order, dtype = np.lib.format.read_array_header_2_0(stream)
    else:
        raise GridFileError(f"{label}: unsupported .npy format version {version}")
    if dtype.hasobject:
        raise GridFileError(f"{label}: the array holds Python objects, which are never loaded")
    if math.prod(shape) > MAX_VOXELS:  # Python ints: a corrupt header cannot overflow this
        raise GridFileError(f"{label}: the header claims an array of shape {shape}, more than "
                            f"the {MAX_VOXELS:,}-voxel limit")
    return shape, fortran_order, dtype


def _npy_data(stream, size: int, header: tuple, label: str) -> np.ndarray:
    """The array after an .npy header, read only if the ``size``-byte stream holds all of it."""
    shape, fortran_order, dtype = header
    count = math.prod(shape)
    n_bytes = count * dtype.itemsize
    available = size - stream.tell()
    data = stream.read(n_bytes) if n_bytes <= available else b""
    if len(data) < n_bytes:
        raise GridFileError(f"{label}: truncated .npy data: the header's {shape} {dtype} array "
                            f"needs {n_bytes:,} bytes, {max(available, 0):,} are left")
    if dtype is bool:  # bytes other than 0/1 would make invalid numpy bools
        flat = np.frombuffer(data, dtype=np.uint8, count=count) != 0
    else:
        flat = np.frombuffer(data, dtype=dtype, count=count).copy()  # writable, like np.load
    return flat.reshape(shape, order="F" if fortran_order else "C")


def _npz_occupancy_key(shapes: dict, name: str) -> str:
    """Which member is the grid: the first of NPZ_ARRAY_NAMES present, else the only 3-D one."""
    for key in NPZ_ARRAY_NAMES:
        if key in shapes:
            return key
    grids = [key for key, shape in shapes.items() if len(shape) == 3]
    if len(grids) == 1:
        return grids[0]
    raise GridFileError(
        f"{name}: cannot tell which array is the grid: no array named "
        f"{'/'.join(NPZ_ARRAY_NAMES)} and {len(grids)} 3-D arrays among {sorted(shapes)}"
    )


def _read_nifti(path: Path) -> VoxelGrid:

    data, affine = _nifti_values(path)
    grid = VoxelGrid(_label_occupancy(data), affine, source=path.name)
    warn_if_merged(data, path.name)  # after the grid: a refused volume is not a label map
    return grid


def _nifti_values(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """(X, Y, Z) voxel values as stored and the header's (4, 4) affine."""
    import nibabel as nib

    name = path.name
    with _reading(name, "not a readable NIfTI file"):
        image = nib.load(path, mmap=False)  # parses the header only
        shape = _drop_trailing_ones(image.shape)  # (X, Y, Z, 1) volumes are common
        guard_size(shape, name)  # before reading the voxel data
        _require_nifti_data(path, image.header, shape)
        return np.asanyarray(image.dataobj).reshape(shape), image.affine


def _require_nifti_data(path: Path, header, shape: tuple) -> None:
    """Refuse a NIfTI file shorter than its header says: nibabel allocates the full voxel array
    before it reads, so a truncated file would cost that memory before failing."""
    if min(shape) < 0:
        raise GridFileError(f"{path.name}: corrupt NIfTI header: negative dimension in {shape}")
    dtype = header.get_data_dtype()
    needed = int(header.get_data_offset()) + math.prod(shape) * dtype.itemsize
    if path.name.lower().endswith(".gz"):
        available = 0
        with gzip.open(path, "rb") as file:  # count the payload without keeping it
            while available < needed:
                chunk = file.read(min(_CHUNK, needed - available))
                if not chunk:
                    break
                available += len(chunk)
    else:
        available = path.stat().st_size
    if available < needed:
        raise GridFileError(f"{path.name}: truncated NIfTI file: the header's {shape} {dtype} "
                            f"voxels need {needed:,} bytes, the file holds {available:,}")


def _drop_trailing_ones(shape: tuple) -> tuple:
    shape = tuple(int(n) for n in shape)
    while len(shape) > 3 and shape[-1] == 1:
        shape = shape[:-1]
    return shape


def _label_occupancy(data: np.ndarray) -> np.ndarray:
    """``data > 0`` for masks and integer labels; other values go to ``as_occupancy`` to refuse.

    Float volumes count as labels only when every value is a whole number (NIfTI writers often
    store masks as float32); a probability map is refused by the grid check with its hint.
    """
    if data.dtype.kind in "biu":
        return data > 0
    if data.dtype.kind == "f" and np.all(np.isfinite(data)) and np.all(data == np.round(data)):
        return data > 0
    return data


def _nifti_bytes(grid: VoxelGrid, gzipped: bool) -> bytes:
    """A single-file NIfTI-1 image: uint8 0/1 voxels, the affine as both sform and qform."""
    import nibabel as nib

    image = nib.Nifti1Image(grid.occupancy.astype(np.uint8), grid.affine)
    image.set_sform(grid.affine, code="scanner")
    image.set_qform(grid.affine, code="scanner")  # the rigid part, for readers that prefer qform
    data = image.to_bytes()
    return gzip.compress(data, compresslevel=6) if gzipped else data


# --- file plumbing ----------------------------------------------------------------------------


def _extension(path, choices) -> str | None:
    """The extension of ``path`` among ``choices`` (longest match, so .nii.gz beats .gz)."""
    name = Path(path).name.lower()
    matches = [ext for ext in choices if name.endswith(ext) and len(name) > len(ext)]
    return max(matches, key=len) if matches else None


def _require_extension(path: Path, choices, kind: str) -> str:
    ext = _extension(path, choices)
    if ext is None:
        raise GridFileError(
            f"{path.name}: unsupported {kind} format '{path.suffix or path.name}'; "
            f"supported: {', '.join(choices)}"
        )
    return ext


def _require_file(path: Path) -> None:
    if not path.exists():
        raise GridFileError(f"{path.name}: file not found ({path})")
    if not path.is_file():
        raise GridFileError(f"{path.name}: not a file ({path})")


def _read_bytes(path: Path) -> bytes:
    try:
        return path.read_bytes()
    except OSError as exc:
        raise GridFileError(f"{path.name}: cannot read the file ({_describe(exc)})") from None


def temp_path(path) -> Path:
    """Where ``path`` is written before it is renamed into place: ``name.tmp-<pid>.<ext>``.

    Same folder (so the rename is atomic), same extension, marked with ``TEMP_MARK`` and the
    writing process's id; ``batch.remove_temp_files`` sweeps those a killed run left behind.
    """
    path = Path(path)
    ext = _extension(path, GRID_EXTENSIONS + MESH_EXTENSIONS) or path.suffix
    stem = path.name[:len(path.name) - len(ext)]
    return path.with_name(f"{stem}{TEMP_MARK}{os.getpid()}{ext}")


def _write_bytes(path: Path, data: bytes) -> None:
    """Write ``data`` to a temporary name, then rename it onto ``path`` (``os.replace`` is atomic):
    a crash, Ctrl-C or kill leaves either the old file or the complete new one, never a part."""
    temp = temp_path(path)
    try:
        temp.write_bytes(data)
        os.replace(temp, path)
    except OSError as exc:
        raise GridFileError(f"{path.name}: cannot write the file ({_describe(exc)})") from None
    finally:
        if temp.exists():  # the write or the rename failed, or was interrupted
            temp.unlink(missing_ok=True)


@contextmanager
def _reading(name: str, problem: str):
    """Turn any exception a file parser raises into one GridFileError naming file and problem.

    Parsers fed corrupt bytes raise nearly anything (numpy's header parser ``TokenError`` or
    ``SyntaxError``, nibabel ``HeaderDataError``, trimesh ``IndexError``, zipfile
    ``NotImplementedError``, ``MemoryError``); the project's own errors pass through unchanged.
    """
    try:
        yield
    except AGNDCError:
        raise
    except Exception as exc:
        raise GridFileError(f"{name}: {problem} ({_describe(exc)})") from None


def _describe(exc: BaseException) -> str:
    """One line for a library exception: its message, or its type when it has none."""
    # some exceptions keep (message, position) in args, which str() shows as a tuple
    message = exc.args[0] if len(exc.args) > 1 and isinstance(exc.args[0], str) else str(exc)
    text = (getattr(exc, "strerror", None) or message).strip()
    return (text.splitlines()[0] if text else "") or type(exc).__name__


# --- label maps read as one mask -------------------------------------------------------------


class MergedLabelsWarning(UserWarning):
    """A label map was read as one mask, so its labels are merged into one solid.

    Attributes:
        source: the file name; labels: (L,) int64 the positive labels that were merged.
    """

    def __init__(self, source: str, labels: np.ndarray):
        self.source, self.labels = source, np.asarray(labels, dtype=np.int64)
        super().__init__(f"{source} holds {len(self.labels)} labels "
                         f"({shown_values(self.labels)}): read as one mask, they are merged into "
                         "one solid")


def warn_if_merged(values: np.ndarray, source: str) -> None:
    """Warn (``MergedLabelsWarning``) when ``values``, about to be read as the mask
    ``values > 0``, hold two or more positive labels."""
    labels = merged_labels(values)
    if labels is not None:
        warnings.warn(MergedLabelsWarning(source, labels),
                      stacklevel=4)  # the caller of load_grid


def refuse_label_map(values: np.ndarray, source: str) -> None:
    """Raise GridError for ``values`` holding two or more positive labels where a binary grid
    is read (.npy, .npz), with what to do instead; other values are left to the grid check."""
    labels = merged_labels(values)
    if labels is not None:
        raise GridError(f"{source}: a label map ({len(labels)} labels: "
                        f"{shown_values(labels)}), not a binary grid: mesh each label on its own "
                        "(agndc remesh --per-label; Blender: Per Label), or threshold it into "
                        "one mask")


def merged_labels(values: np.ndarray) -> np.ndarray | None:
    """(L,) int64 the positive labels of (X, Y, Z) ``values`` when there are two or more (the
    volume is a label map, not a mask), else None. Only integers and whole-number floats are
    labels."""
    if values.dtype.kind not in "iuf":
        return None
    positive = values[values > 0]
    if positive.size == 0 or positive.min() == positive.max():  # one label: a plain mask
        return None
    if values.dtype.kind == "f" and not np.all(positive == np.round(positive)):
        return None
    return np.unique(positive).astype(np.int64)


def shown_values(values, limit: int = 12) -> str:
    """'1, 3, 7' (at most ``limit`` values, then '... (N in all)')."""
    values = [int(v) for v in values]
    text = ", ".join(map(str, values[:limit]))
    return text + (f", ... ({len(values)} in all)" if len(values) > limit else "")
