"""Grid and mesh file I/O: round trips for every format, placement, clear errors for bad files."""

import importlib.util
import struct
import tracemalloc
import zipfile
from pathlib import Path

import numpy as np
import pytest

from agndc_core.errors import GridError, GridFileError, MeshError
from agndc_core.grid import VoxelGrid
from agndc_core.gridio import (
    GRID_EXTENSIONS,
    grid_model_count,
    is_grid_path,
    is_mesh_path,
    load_grid,
    load_mesh,
    save_grid,
    save_mesh,
)

SHARED = Path(__file__).parents[2].parent / "shared"
CHAIR_BINVOX = SHARED / "data" / "dev" / "binvox" / "trimesh_chair_model.binvox"

#: a general affine: anisotropic spacing, a small rotation/shear and a translation
GENERAL_AFFINE = np.array([
    [0.5, 0.05, 0.0, -3.0],
    [0.0, 0.7, 0.0, 12.5],
    [0.0, 0.0, 1.2, 0.25],
    [0.0, 0.0, 0.0, 1.0],
])
ISOTROPIC = VoxelGrid.from_spacing(np.ones((1, 1, 1), bool), 0.3, (1.0, -2.0, 0.5)).affine
#: what each format keeps of the affine: "all", "isotropic" (binvox) or "none" (identity on load)
PLACEMENT = {".npy": "none", ".npz": "all", ".binvox": "isotropic", ".vox": "none",
             ".nii": "all", ".nii.gz": "all"}


def sparse_grid(shape=(7, 5, 9), fill=0.2, seed=0) -> np.ndarray:
    return np.random.default_rng(seed).random(shape) < fill


def vox_bytes(models) -> bytes:
    """A .vox file built by hand: ``models`` is a list of (size (3,), xyz (N, 3)) pairs."""
    def chunk(chunk_id, content, children=b""):
        return struct.pack("<4sii", chunk_id, len(content), len(children)) + content + children

    children = chunk(b"PACK", struct.pack("<i", len(models)))
    for size, xyz in models:
        xyzi = np.concatenate([np.asarray(xyz), np.full((len(xyz), 1), 7)], axis=1)
        children += chunk(b"SIZE", struct.pack("<3i", *size))
        children += chunk(b"XYZI", struct.pack("<i", len(xyz)) + xyzi.astype(np.uint8).tobytes())
    children += chunk(b"RGBA", bytes(4 * 256))  # a palette after the models is skipped
    return b"VOX " + struct.pack("<i", 150) + chunk(b"MAIN", b"", children)


# --- round trips --------------------------------------------------------------------------------


@pytest.mark.parametrize("ext", GRID_EXTENSIONS)
def test_grid_round_trip(tmp_path, ext):
    occupancy = sparse_grid()
    affine = ISOTROPIC if PLACEMENT[ext] == "isotropic" else GENERAL_AFFINE
    path = tmp_path / f"part{ext}"
    save_grid(VoxelGrid(occupancy, affine), path)
    loaded = load_grid(path)
    assert loaded.occupancy.dtype == bool
    np.testing.assert_array_equal(loaded.occupancy, occupancy)
    expected = np.eye(4) if PLACEMENT[ext] == "none" else affine
    # NIfTI stores the affine as float32
    np.testing.assert_allclose(loaded.affine, expected, atol=1e-6)
    assert loaded.source == path.name


@pytest.mark.parametrize("ext", [".binvox", ".vox", ".npz"])
def test_round_trip_full_and_empty_grids(tmp_path, ext):
    """Long runs (binvox counts stop at 255) and the empty grid, which must load."""
    for occupancy in (np.ones((20, 17, 23), bool), np.zeros((3, 4, 5), bool)):
        save_grid(VoxelGrid(occupancy), tmp_path / f"g{ext}")
        np.testing.assert_array_equal(load_grid(tmp_path / f"g{ext}").occupancy, occupancy)


def test_nifti_keeps_affine_and_reads_labels(tmp_path):
    nib = pytest.importorskip("nibabel")
    affine = np.diag([0.5, 0.7, 1.2, 1.0])
    affine[:3, 3] = (10.0, -4.0, 2.5)
    labels = np.random.default_rng(1).integers(0, 6, size=(7, 5, 9)).astype(np.int16)
    nib.save(nib.Nifti1Image(labels[..., None], affine), tmp_path / "seg.nii.gz")  # (X, Y, Z, 1)
    grid = load_grid(tmp_path / "seg.nii.gz")
    np.testing.assert_array_equal(grid.occupancy, labels > 0)
    np.testing.assert_allclose(grid.affine, affine)
    np.testing.assert_allclose(grid.index_to_world([[2, 1, 3]]), [[11.0, -3.3, 6.1]])


def test_nifti_refuses_probability_map(tmp_path):
    nib = pytest.importorskip("nibabel")
    probabilities = np.random.default_rng(2).random((4, 4, 4)).astype(np.float32)
    nib.save(nib.Nifti1Image(probabilities, np.eye(4)), tmp_path / "p.nii")
    with pytest.raises(GridError, match="threshold"):
        load_grid(tmp_path / "p.nii")


def test_corrupt_nifti_headers(tmp_path):
    """nibabel's HeaderDataError is wrapped; claimed sizes are checked before nibabel allocates."""
    nib = pytest.importorskip("nibabel")
    data = nib.Nifti1Image(sparse_grid().astype(np.int16), np.eye(4)).to_bytes()

    def corrupt(name, offset, code, *values):
        out = bytearray(data)
        struct.pack_into(code, out, offset, *values)
        (tmp_path / name).write_bytes(bytes(out))
        return tmp_path / name

    with pytest.raises(GridFileError, match="type.nii: .*data code"):
        load_grid(corrupt("type.nii", 70, "<h", -1))  # datatype
    # dim[1..3] at byte 42: 500^3 int16 is 250 MB that the file does not hold
    path = corrupt("big.nii", 42, "<3h", 500, 500, 500)
    assert refused_peak_bytes(path, GridFileError, "big.nii: truncated NIfTI") < 1_000_000
    path = corrupt("huge.nii", 42, "<3h", 32767, 32767, 32767)
    assert refused_peak_bytes(path, GridError, "huge.nii.*voxels, more than") < 1_000_000


# --- npy / npz ----------------------------------------------------------------------------------


def test_npy_float_binary_loads_and_labels_are_refused(tmp_path):
    occupancy = sparse_grid()
    np.save(tmp_path / "f.npy", occupancy.astype(np.float32))
    np.testing.assert_array_equal(load_grid(tmp_path / "f.npy").occupancy, occupancy)
    np.save(tmp_path / "labels.npy", np.arange(6 * 2 * 3).reshape(6, 2, 3) % 6)
    with pytest.raises(GridError, match="labels.npy.*binary"):
        load_grid(tmp_path / "labels.npy")


def test_npz_array_choice_and_spacing(tmp_path):
    occupancy = sparse_grid()
    np.savez(tmp_path / "a.npz", voxels=occupancy, voxel_size=0.25, origin=[1.0, 2.0, 3.0])
    grid = load_grid(tmp_path / "a.npz")
    np.testing.assert_array_equal(grid.occupancy, occupancy)
    np.testing.assert_allclose(grid.voxel_size, 0.25)
    np.testing.assert_allclose(grid.origin, [1.0, 2.0, 3.0])
    np.savez(tmp_path / "only.npz", whatever=occupancy, note=np.arange(3))
    np.testing.assert_array_equal(load_grid(tmp_path / "only.npz").occupancy, occupancy)
    np.savez(tmp_path / "two.npz", a=occupancy, b=occupancy)
    with pytest.raises(GridFileError, match="two.npz.*which array"):
        load_grid(tmp_path / "two.npz")


def test_corrupt_npy_and_npz(tmp_path):
    (tmp_path / "bad.npy").write_bytes(b"\x93NUMPY\x01\x00garbage")
    (tmp_path / "bad.npz").write_bytes(b"PK\x03\x04 not really a zip")
    np.save(tmp_path / "array.npy", sparse_grid())
    (tmp_path / "array.npy").rename(tmp_path / "array.npz")
    for name in ("bad.npy", "bad.npz", "array.npz"):
        with pytest.raises(GridFileError, match=name):
            load_grid(tmp_path / name)


def npy_bytes(header: str, data: bytes = b"") -> bytes:
    """A version 1.0 .npy file with a hand-written header dict (padded as numpy pads it)."""
    text = header.encode("latin1")
    text += b" " * (-(len(text) + 11) % 64) + b"\n"
    return b"\x93NUMPY\x01\x00" + struct.pack("<H", len(text)) + text + data


def refused_peak_bytes(path, error, match) -> int:
    """Load ``path``, expect ``error`` matching ``match``; return the peak memory it took."""
    tracemalloc.start()
    try:
        with pytest.raises(error, match=match):
            load_grid(path)
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_corrupt_npy_header_is_a_grid_file_error(tmp_path):
    """numpy's header parser raises TokenError/SyntaxError on these; they must not leak."""
    cut = "{'descr': '|b1', 'fortran_order': False, 'shape': (6, 5, 7"
    for index, header in enumerate([cut, cut + "x\x01}", "{'descr': 'O', 'fortran_order': False, "
                                    "'shape': (2, 2, 2), }"]):
        (tmp_path / f"h{index}.npy").write_bytes(npy_bytes(header))
        with pytest.raises(GridFileError, match=f"h{index}.npy"):
            load_grid(tmp_path / f"h{index}.npy")
    with zipfile.ZipFile(tmp_path / "inner.npz", "w") as archive:  # the same header in an .npz
        archive.writestr("occupancy.npy", npy_bytes(cut))
    with pytest.raises(GridFileError, match="inner.npz: member occupancy.npy"):
        load_grid(tmp_path / "inner.npz")


def test_huge_npy_headers_are_refused_before_allocating(tmp_path):
    claims = {"huge": "(100000, 100000, 100000)", "wraps": "(4294967296, 4294967296, 1)",
              "big": "(500, 500, 500)"}  # 1 GB of float64: under the voxel limit, not in the file
    for name, shape in claims.items():
        header = f"{{'descr': '<f8', 'fortran_order': False, 'shape': {shape}, }}"
        (tmp_path / f"{name}.npy").write_bytes(npy_bytes(header, bytes(64)))
        problem = "truncated" if name == "big" else "voxel limit"
        peak = refused_peak_bytes(tmp_path / f"{name}.npy", GridFileError, f"{name}.npy.*{problem}")
        assert peak < 1_000_000


# --- binvox -------------------------------------------------------------------------------------


def test_binvox_header_comments_and_placement(tmp_path):
    occupancy = sparse_grid((4, 4, 4), seed=3)
    payload = np.stack([occupancy.transpose(0, 2, 1).ravel(), np.ones(64, bool)], 1)  # runs of 1
    header = (b"#binvox 1\n# a comment line\n\n  dim 4 4 4\t# inline comment\n"
              b"translate 1 2 3\n# another\nscale 2\ndata\n")
    (tmp_path / "c.binvox").write_bytes(header + payload.astype(np.uint8).tobytes())
    grid = load_grid(tmp_path / "c.binvox")
    np.testing.assert_array_equal(grid.occupancy, occupancy)
    # spec: centre of voxel i = translate + (i + 0.5) * scale / dim
    np.testing.assert_allclose(grid.index_to_world([[0, 0, 0], [3, 1, 2]]),
                               [[1.25, 2.25, 3.25], [2.75, 2.75, 4.25]])


def test_binvox_matches_trimesh_reader():
    if not CHAIR_BINVOX.exists():
        pytest.skip("../shared/data/dev/binvox is not beside the checkout")
    import trimesh

    grid = load_grid(CHAIR_BINVOX)
    reference = trimesh.load(CHAIR_BINVOX)
    np.testing.assert_array_equal(grid.occupancy, reference.matrix)
    assert grid.occupancy.sum() == 1932
    # trimesh maps the first/last voxel centres to translate/translate+scale, the spec maps the
    # grid's outer faces there: the two placements differ by at most half a voxel
    indices = np.argwhere(grid.occupancy)
    difference = np.abs(grid.index_to_world(indices) - reference.indices_to_points(indices))
    assert difference.max() <= 0.5 * grid.voxel_size[0] + 1e-9
    lo = grid.origin - 0.5 * grid.voxel_size
    hi = grid.origin + (np.array(grid.shape) - 0.5) * grid.voxel_size
    np.testing.assert_allclose(lo, reference.translation, atol=1e-9)
    np.testing.assert_allclose(hi - lo, reference.scale * (np.array(grid.shape) - 1), atol=1e-9)


def test_truncated_binvox(tmp_path):
    save_grid(VoxelGrid(sparse_grid()), tmp_path / "part.binvox")
    data = (tmp_path / "part.binvox").read_bytes()
    (tmp_path / "part.binvox").write_bytes(data[:-5])
    with pytest.raises(GridFileError, match=r"part.binvox: truncated RLE data: \d+ of 315 voxels"):
        load_grid(tmp_path / "part.binvox")
    (tmp_path / "head.binvox").write_bytes(data[:30])
    with pytest.raises(GridFileError, match="head.binvox.*data"):
        load_grid(tmp_path / "head.binvox")
    (tmp_path / "no.binvox").write_bytes(b"\x00\x01 random bytes")
    with pytest.raises(GridFileError, match="not a binvox file"):
        load_grid(tmp_path / "no.binvox")


def test_binvox_huge_dims_are_refused(tmp_path):
    """Sizes beyond int64 or whose product wraps int64 (2**32 cubed is 0 mod 2**64)."""
    for index, dims in enumerate(["4294967296 4294967296 4294967296", "1" + "0" * 30]):
        path = tmp_path / f"d{index}.binvox"
        path.write_bytes(f"#binvox 1\ndim {dims}\ndata\n".encode() + bytes([1, 255]))
        with pytest.raises(GridError, match=f"d{index}.binvox.*more than"):
            load_grid(path)


def test_binvox_refuses_anisotropic_affine(tmp_path):
    grid = VoxelGrid.from_spacing(sparse_grid(), (1.0, 1.0, 2.0))
    with pytest.raises(GridFileError, match="axis-aligned"):
        save_grid(grid, tmp_path / "a.binvox")


# --- MagicaVoxel --------------------------------------------------------------------------------


def test_vox_two_models(tmp_path):
    first = ((3, 3, 3), [[0, 0, 0]])
    second = ((4, 2, 5), [[3, 1, 4], [0, 0, 0], [2, 1, 0]])
    (tmp_path / "two.vox").write_bytes(vox_bytes([first, second]))
    grid = load_grid(tmp_path / "two.vox", model_index=1)
    assert grid.shape == (4, 2, 5)
    np.testing.assert_array_equal(np.argwhere(grid.occupancy), [[0, 0, 0], [2, 1, 0], [3, 1, 4]])
    assert load_grid(tmp_path / "two.vox").shape == (3, 3, 3)
    with pytest.raises(GridFileError, match="2 models"):
        load_grid(tmp_path / "two.vox", model_index=2)
    assert grid_model_count(tmp_path / "two.vox") == 2


def test_grid_model_count(tmp_path):
    (tmp_path / "one.vox").write_bytes(vox_bytes([((3, 3, 3), [[0, 0, 0]])]))
    np.save(tmp_path / "a.npy", sparse_grid())
    assert grid_model_count(tmp_path / "one.vox") == 1
    assert grid_model_count(tmp_path / "a.npy") == 1
    (tmp_path / "garbage.vox").write_bytes(b"this is not a voxel file at all")
    with pytest.raises(GridFileError, match="garbage.vox.*not a MagicaVoxel"):
        grid_model_count(tmp_path / "garbage.vox")
    with pytest.raises(GridFileError, match="no such file|not found|missing|exist"):
        grid_model_count(tmp_path / "missing.vox")


def test_bad_vox_files(tmp_path):
    (tmp_path / "garbage.vox").write_bytes(b"this is not a voxel file at all")
    (tmp_path / "cut.vox").write_bytes(vox_bytes([((3, 3, 3), [[0, 0, 0], [1, 1, 1]])])[:40])
    (tmp_path / "out.vox").write_bytes(vox_bytes([((2, 2, 2), [[0, 5, 0]])]))
    for name, problem in [("garbage.vox", "not a MagicaVoxel"), ("cut.vox", "truncated"),
                          ("out.vox", "outside")]:
        with pytest.raises(GridFileError, match=f"{name}.*{problem}"):
            load_grid(tmp_path / name)
    with pytest.raises(GridFileError, match="256"):
        save_grid(VoxelGrid(np.zeros((300, 2, 2), bool)), tmp_path / "big.vox")
    # int32 sizes whose product overflows int64 must still be refused before allocating
    (tmp_path / "huge.vox").write_bytes(vox_bytes([((2**31 - 1,) * 3, [[0, 0, 0]])]))
    with pytest.raises(GridError, match="huge.vox.*more than"):
        load_grid(tmp_path / "huge.vox")


# --- paths and errors ---------------------------------------------------------------------------


def test_extension_checks():
    assert is_grid_path("scan.nii.gz") and is_grid_path("A.BINVOX") and is_grid_path(Path("g.npz"))
    assert not is_grid_path("mesh.obj") and not is_grid_path("archive.gz")
    assert is_mesh_path("part.STL") and not is_mesh_path("scan.nii.gz")


def test_missing_and_unsupported_files(tmp_path):
    with pytest.raises(GridFileError, match="nothing.npy: file not found"):
        load_grid(tmp_path / "nothing.npy")
    (tmp_path / "grid.hdf5").write_bytes(b"x")
    with pytest.raises(GridFileError, match="grid.hdf5: unsupported"):
        load_grid(tmp_path / "grid.hdf5")
    with pytest.raises(GridFileError, match="unsupported"):
        save_grid(VoxelGrid(sparse_grid()), tmp_path / "grid.tiff")
    (tmp_path / "bad.nii.gz").write_bytes(b"not gzip")
    with pytest.raises(GridFileError, match="bad.nii.gz"):
        load_grid(tmp_path / "bad.nii.gz")


# --- meshes -------------------------------------------------------------------------------------


@pytest.mark.parametrize("ext", [".obj", ".ply", ".glb"])
def test_mesh_round_trip_keeps_vertex_order(tmp_path, ext):
    vertices = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=np.float64)
    faces = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    save_mesh(vertices, faces, tmp_path / f"tet{ext}")
    loaded_vertices, loaded_faces = load_mesh(tmp_path / f"tet{ext}")
    assert loaded_vertices.dtype == np.float64 and loaded_faces.dtype == np.int64
    np.testing.assert_allclose(loaded_vertices, vertices)
    np.testing.assert_array_equal(loaded_faces, faces)


def test_mesh_errors(tmp_path):
    (tmp_path / "points.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n")
    with pytest.raises(MeshError, match="points.obj.*no faces"):
        load_mesh(tmp_path / "points.obj")
    (tmp_path / "nan.obj").write_text("v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(MeshError, match="nan.obj.*non-finite"):
        load_mesh(tmp_path / "nan.obj")
    (tmp_path / "broken.ply").write_bytes(b"\x00garbage")
    with pytest.raises(GridFileError, match="broken.ply"):
        load_mesh(tmp_path / "broken.ply")
    (tmp_path / "range.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n")
    with pytest.raises((GridFileError, MeshError), match="range.obj"):
        load_mesh(tmp_path / "range.obj")
    # non-UTF-8 text: trimesh guesses its encoding only with the optional charset_normalizer
    (tmp_path / "latin1.obj").write_bytes(b"# caf\xe9\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    if importlib.util.find_spec("charset_normalizer") is None:
        with pytest.raises(GridFileError, match="latin1.obj.*not UTF-8"):
            load_mesh(tmp_path / "latin1.obj")
    else:
        assert load_mesh(tmp_path / "latin1.obj")[1].shape == (1, 3)
    with pytest.raises(GridFileError, match="missing.stl"):
        load_mesh(tmp_path / "missing.stl")
    # random bytes: named as unreadable, whatever encoding trimesh could guess for them
    (tmp_path / "noise.stl").write_bytes(np.random.default_rng(12).bytes(3000))
    with pytest.raises(GridFileError, match="noise.stl: cannot read the mesh: neither a binary"):
        load_mesh(tmp_path / "noise.stl")
    with pytest.raises(GridFileError, match="unsupported"):
        save_mesh(np.eye(3), [[0, 1, 2]], tmp_path / "out.fbx")
