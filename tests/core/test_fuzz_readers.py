"""Fuzzing the grid and mesh readers: a corrupt file is either read into a valid result or
refused with the project's own error naming the file; never another exception type, a hang or a
huge allocation.

Each format starts from a small valid file built here and is mutated with byte flips,
truncations, inserted junk, deleted slices and header fields overwritten with huge numbers.
Compressed containers (.npz, .nii.gz) are mutated both as stored and inside (the mutated
payload is compressed again), so the inner parser sees corrupt data too. Seeded and fast.
"""

import gzip
import io
import re
import signal
import struct
import threading
import time
import zipfile
from collections import Counter
from collections.abc import Callable

import numpy as np
import pytest
import trimesh

from agndc_core.errors import GridError, GridFileError, MeshError
from agndc_core.grid import VoxelGrid
from agndc_core.gridio import load_grid, load_mesh, save_grid

GRID_FORMATS = (".npy", ".npz", ".binvox", ".vox", ".nii", ".nii.gz")
MESH_FORMATS = (".obj", ".stl", ".ply")
MUTANTS_PER_FORMAT = 150
#: a read still running after this many seconds has hung (a hang guard, not a speed test: a
#: reader that loops on a hostile header never returns; a loaded machine is slow, not stuck)
HANG_S = 60.0
SEED = 1414
#: huge or hostile replacements for numbers in text headers (npy dict, binvox, ply, obj)
HUGE_TEXT = (b"4294967296", b"99999999999999999999999", b"-1", b"0", b"2147483647", b"1e308",
             b"nan")
#: huge or hostile values for binary integer fields, by struct code
HUGE_BINARY = {"<h": (-1, 32767, 0, -32768), "<i": (-1, 2**31 - 1, 0, -(2**31), 65536),
               "<I": (2**32 - 1, 2**31, 0), "<f": (float("inf"), float("nan"), 1e30, -1.0, 0.0)}


# corrupt input makes trimesh and nibabel warn (overflowing casts, deprecated parsing paths);
# what matters here is what they raise, so the noise is kept out of the report
pytestmark = pytest.mark.filterwarnings("ignore::RuntimeWarning", "ignore::DeprecationWarning")


class ReadTimedOut(BaseException):
    """Raised by the alarm inside a read; a BaseException so no reader can swallow it."""


# --- valid seed files ---------------------------------------------------------------------------


def _grid() -> np.ndarray:
    return np.random.default_rng(3).random((6, 5, 7)) < 0.4  # (X, Y, Z) bool


def _npz(members: dict) -> bytes:
    """A zip of raw .npy member bytes, as np.savez_compressed writes it."""
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as archive:
        for key, data in members.items():
            archive.writestr(f"{key}.npy", data)
    return buffer.getvalue()


def _npy(array: np.ndarray) -> bytes:
    buffer = io.BytesIO()
    np.save(buffer, array)
    return buffer.getvalue()


def _nifti() -> bytes:
    nib = pytest.importorskip("nibabel")
    affine = np.diag([0.5, 0.7, 1.2, 1.0])
    affine[:3, 3] = (10.0, -4.0, 2.5)
    labels = (_grid() * np.arange(7)).astype(np.int16)[..., None]  # (X, Y, Z, 1) labels
    return nib.Nifti1Image(labels, affine).to_bytes()


def _saved_grid(tmp_path, ext: str) -> bytes:
    """The project's own writer (binvox, vox)."""
    path = tmp_path / f"seed{ext}"
    save_grid(VoxelGrid.from_spacing(_grid(), 0.25, (1.0, 2.0, 3.0)), path)
    return path.read_bytes()


def _mesh(file_type: str, **options) -> bytes:
    box = trimesh.creation.box((1.0, 0.6, 0.4))
    data = box.export(file_type=file_type, **options)
    return data.encode("utf-8") if isinstance(data, str) else data


def _seeds(tmp_path, ext: str) -> list[tuple[bytes, Callable | None]]:
    """[(payload, wrap)]: the file is the payload, or ``wrap(payload)`` for a container
    (mutations then go to either side of ``wrap``)."""
    occupancy = _grid()
    if ext == ".npy":
        return [(_npy(occupancy), None), (_npy(occupancy.astype(np.float32)), None)]
    if ext == ".npz":
        affine = _npy(np.diag([0.5, 0.5, 0.5, 1.0]))
        return [(_npy(occupancy), lambda data: _npz({"occupancy": data, "affine": affine}))]
    if ext in (".binvox", ".vox"):
        return [(_saved_grid(tmp_path, ext), None)]
    if ext == ".nii":
        return [(_nifti(), None)]
    if ext == ".nii.gz":
        return [(_nifti(), gzip.compress)]
    if ext == ".obj":
        return [(_mesh("obj"), None)]
    if ext == ".stl":
        return [(_mesh("stl"), None), (_mesh("stl_ascii"), None)]
    return [(_mesh("ply"), None), (_mesh("ply", encoding="ascii"), None)]


#: binary header fields worth overwriting with huge values: (offset, struct code)
BINARY_FIELDS = {
    # NIfTI-1: sizeof_hdr, dim[0..7], datatype, bitpix, vox_offset, scl_slope, qform/sform codes
    ".nii": [(0, "<i")] + [(40 + 2 * i, "<h") for i in range(8)]
    + [(70, "<h"), (72, "<h"), (108, "<f"), (112, "<f"), (252, "<h"), (254, "<h")],
    ".stl": [(80, "<I")],  # binary STL: the triangle count
}


def _vox_fields(data: bytes) -> list[tuple[int, str]]:
    """Chunk sizes, model sizes and voxel counts of a .vox file."""
    fields = []
    for match in re.finditer(rb"MAIN|SIZE|XYZI", data):
        start = match.start() + 4
        fields += [(start, "<i"), (start + 4, "<i"), (start + 8, "<i")]
        if match.group() == b"SIZE":
            fields += [(start + 12, "<i"), (start + 16, "<i")]
    return fields


# --- mutations ----------------------------------------------------------------------------------


def _position(data: bytes, rng) -> int:
    """Half the time inside the first 400 bytes, where headers live."""
    span = min(len(data), 400) if rng.random() < 0.5 else len(data)
    return int(rng.integers(0, max(span, 1)))


def _flip(data: bytes, rng, ext: str) -> bytes:
    out = bytearray(data)
    for _ in range(int(rng.integers(1, 5))):
        out[_position(data, rng)] ^= int(rng.integers(1, 256))
    return bytes(out)


def _truncate(data: bytes, rng, ext: str) -> bytes:
    return data[: int(rng.integers(0, len(data)))]


def _insert(data: bytes, rng, ext: str) -> bytes:
    junk = rng.integers(0, 256, size=int(rng.integers(1, 65)), dtype=np.uint8).tobytes()
    if rng.random() < 0.3:
        junk = b"\n" * len(junk) if rng.random() < 0.5 else b"(" * len(junk)
    at = _position(data, rng)
    return data[:at] + junk + data[at:]


def _delete(data: bytes, rng, ext: str) -> bytes:
    at = _position(data, rng)
    return data[:at] + data[at + int(rng.integers(1, 33)):]


def _huge(data: bytes, rng, ext: str) -> bytes:
    """Overwrite a header number: a digit run in a text header, or a known binary field."""
    fields = _vox_fields(data) if ext == ".vox" else BINARY_FIELDS.get(ext.removesuffix(".gz"), [])
    if ext == ".stl" and data.lstrip().startswith(b"solid"):
        fields = []  # ASCII STL
    fields = [(offset, code) for offset, code in fields
              if offset + struct.calcsize(code) <= len(data)]
    if fields:
        offset, code = fields[int(rng.integers(len(fields)))]
        values = HUGE_BINARY[code]
        out = bytearray(data)
        struct.pack_into(code, out, offset, values[int(rng.integers(len(values)))])
        return bytes(out)
    runs = list(re.finditer(rb"-?\d+(\.\d+)?", data[:1024]))
    if not runs:
        return _flip(data, rng, ext)
    run = runs[int(rng.integers(len(runs)))]
    number = HUGE_TEXT[int(rng.integers(len(HUGE_TEXT)))]
    return data[: run.start()] + number + data[run.end():]


MUTATIONS = (_flip, _truncate, _insert, _delete, _huge)


def _mutants(seeds, ext: str, rng):
    """Yield (mutation name, file bytes): mutations cycle so every kind is tried equally."""
    for i in range(MUTANTS_PER_FORMAT):
        payload, wrap = seeds[i % len(seeds)]
        mutate = MUTATIONS[i % len(MUTATIONS)]
        if wrap is None:
            yield mutate.__name__[1:], mutate(payload, rng, ext)
        elif (i // len(MUTATIONS)) % 2:  # corrupt a container's payload, then wrap it again
            yield f"{mutate.__name__[1:]}-inner", wrap(mutate(payload, rng, ext))
        else:  # the container's own bytes: no format-specific header fields
            yield mutate.__name__[1:], mutate(wrap(payload), rng, "")


# --- checks -------------------------------------------------------------------------------------


def _alarm(signum, frame):
    raise ReadTimedOut


def _timed_read(read, path):
    """(result or None, exception or None, seconds); a read that hangs is interrupted."""
    main_thread = threading.current_thread() is threading.main_thread()
    use_alarm = hasattr(signal, "setitimer") and main_thread
    if use_alarm:
        previous = signal.signal(signal.SIGALRM, _alarm)
        signal.setitimer(signal.ITIMER_REAL, HANG_S)
    start = time.perf_counter()
    try:
        return read(path), None, time.perf_counter() - start
    except Exception as exc:  # judged by the caller
        return None, exc, time.perf_counter() - start
    except ReadTimedOut:
        raise AssertionError(f"{path.name}: reading hung (stopped after {HANG_S} s)") from None
    finally:
        if use_alarm:
            signal.setitimer(signal.ITIMER_REAL, 0)
            signal.signal(signal.SIGALRM, previous)


def _check_grid(grid) -> None:
    assert isinstance(grid, VoxelGrid) and grid.occupancy.flags.writeable
    assert grid.occupancy.dtype == bool and grid.occupancy.ndim == 3
    assert grid.affine.shape == (4, 4) and np.all(np.isfinite(grid.affine))


def _check_mesh(mesh) -> None:
    vertices, faces = mesh
    assert vertices.dtype == np.float64 and vertices.ndim == 2 and vertices.shape[1] == 3
    assert faces.dtype == np.int64 and faces.ndim == 2 and faces.shape[1] == 3
    assert len(faces) > 0 and np.all(np.isfinite(vertices))
    assert faces.min() >= 0 and faces.max() < len(vertices)


@pytest.mark.parametrize("ext", GRID_FORMATS + MESH_FORMATS)
def test_corrupt_files_are_read_or_refused(tmp_path, ext):
    is_mesh = ext in MESH_FORMATS
    read, check = (load_mesh, _check_mesh) if is_mesh else (load_grid, _check_grid)
    clean_errors = (MeshError, GridFileError) if is_mesh else (GridError, GridFileError)
    seeds = _seeds(tmp_path, ext)
    for index, (payload, wrap) in enumerate(seeds):  # the seeds themselves read (and warm up)
        (tmp_path / f"seed{index}{ext}").write_bytes(payload if wrap is None else wrap(payload))
        check(read(tmp_path / f"seed{index}{ext}"))
    rng = np.random.default_rng([SEED, (GRID_FORMATS + MESH_FORMATS).index(ext)])
    outcomes = Counter()
    for number, (mutation, data) in enumerate(_mutants(seeds, ext, rng)):
        path = tmp_path / f"m{number:03d}-{mutation}{ext}"
        path.write_bytes(data)
        result, error, _ = _timed_read(read, path)
        if error is None:
            check(result)
            outcomes["read fine"] += 1
            continue
        if not isinstance(error, clean_errors):
            raise AssertionError(f"{path.name}: leaked {type(error).__name__}: {error}") from error
        assert path.name in str(error), f"the message does not name the file: {error}"
        outcomes[f"refused ({type(error).__name__})"] += 1
    tried = sum(outcomes.values())
    counts = ", ".join(f"{outcome} {count}" for outcome, count in sorted(outcomes.items()))
    print(f"\n{ext:8s} tried {tried}: {counts}")
    assert tried == MUTANTS_PER_FORMAT
    assert tried - outcomes["read fine"] > 0, "no mutant was refused: the mutations miss the file"
