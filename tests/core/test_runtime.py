"""The numpy runtime against torch: the shipped networks give the same vertices without torch."""

import subprocess
import sys

import numpy as np
import pytest

from agndc_core.checkpoint import default_checkpoint_path, load_checkpoint, read_safetensors
from agndc_core.errors import AGNDCError, ModelError
from agndc_core.grid import pad_to_lattice
from agndc_core.inference import predict_lattice
from agndc_core.runtime import Network, load_network
from agndc_core.runtime.parallel import get_threads, set_threads
from agndc_core.study.shapes import generate_shape
from agndc_core.voxelize import voxelize

#: the issue's bound on the runtimes' disagreement, in voxels (measured: ~1e-5)
PARITY_VOXELS = 1e-4
#: the shipped checkpoints (weights/<name>.safetensors): the distilled and the full AGNDC, UNDC
SHIPPED = ["agndc_student", "agndc", "undc"]


def cad_lattice(size: int, seed: int) -> np.ndarray:
    vertices, faces = generate_shape(seed)
    return pad_to_lattice(voxelize(vertices, faces, size).occupancy)


@pytest.fixture(scope="module", params=SHIPPED)
def shipped(request):
    path = default_checkpoint_path(request.param)
    if not path.exists():
        pytest.skip(f"no shipped {request.param} weights")
    return load_checkpoint(path)[0], load_network(path)


@pytest.mark.parametrize("size, seed, tile", [
    (24, 1, 0), (40, 2, 0),
    pytest.param(56, 3, 0, marks=pytest.mark.slow),
    pytest.param(56, 3, 24, marks=pytest.mark.slow)])
def test_shipped_networks_match_torch(shipped, size, seed, tile):
    """Vertices within 1e-4 voxel of the torch path, untiled and tiled (then both tile alike);
    edge probabilities within 1e-4 too."""
    model, network = shipped
    lattice = cad_lattice(size, seed)
    ours = predict_lattice(network, lattice, tile=tile)
    reference = predict_lattice(model, lattice, tile=tile)
    for a, b in zip(ours, reference):
        assert a.shape == b.shape and a.dtype == b.dtype == np.float32
        assert np.abs(a - b).max() <= PARITY_VOXELS


def test_a_grid_with_margins_is_reframed_alike(shipped):
    model, network = shipped
    lattice = np.pad(cad_lattice(24, 4), ((5, 0), (0, 3), (2, 2)))
    for a, b in zip(predict_lattice(network, lattice), predict_lattice(model, lattice)):
        assert np.abs(a - b).max() <= PARITY_VOXELS


def test_threads_do_not_change_the_result():
    network = load_network(default_checkpoint_path("agndc"))
    lattice = cad_lattice(40, 5)
    before = get_threads()
    try:
        set_threads(1)
        one = predict_lattice(network, lattice)[0]
        set_threads(3)
        three = predict_lattice(network, lattice)[0]
    finally:
        set_threads(before)
    np.testing.assert_array_equal(one, three)  # each chunk is computed the same either way


def test_read_safetensors_matches_the_library(tmp_path):
    from safetensors.torch import load_file

    path = default_checkpoint_path("agndc")
    ours = read_safetensors(path)
    theirs = load_file(str(path))
    assert ours.keys() == theirs.keys()
    for key, value in theirs.items():
        np.testing.assert_array_equal(ours[key], value.numpy())
    damaged = tmp_path / "bad.safetensors"
    damaged.write_bytes(path.read_bytes()[:1000])
    with pytest.raises(ModelError, match="cannot read weights"):
        read_safetensors(damaged)


def test_dense_mode_and_cuda_need_torch():
    network = load_network(default_checkpoint_path("agndc"))
    lattice = cad_lattice(16, 6)
    with pytest.raises(AGNDCError, match="numpy runtime"):
        predict_lattice(network, lattice, mode="dense")
    with pytest.raises(AGNDCError, match="numpy runtime"):
        predict_lattice(network, lattice, device="cuda")


def test_network_from_torch_equals_the_loaded_checkpoint():
    path = default_checkpoint_path("agndc")
    twin = Network.from_torch(load_checkpoint(path)[0])
    loaded = load_network(path)
    lattice = cad_lattice(24, 7)
    np.testing.assert_array_equal(predict_lattice(twin, lattice)[0],
                                  predict_lattice(loaded, lattice)[0])


def test_remeshing_a_grid_never_imports_torch():
    """The product path (grid -> learned network -> mesh) runs without torch installed: any
    import of torch in it raises here."""
    code = """
import builtins, sys
real = builtins.__import__
def guarded(name, *args, **kwargs):
    if name == "torch" or name.startswith("torch."):
        raise ImportError("torch imported on the product path")
    return real(name, *args, **kwargs)
builtins.__import__ = guarded
import numpy as np
from agndc_core.pipeline import remesh, remesh_mesh
x, y, z = np.meshgrid(*[np.arange(18)] * 3, indexing="ij")
for method in ("agndc", "undc", "surfacenets", "mc"):
    result = remesh(((x - 8) ** 2 + (y - 9) ** 2 + (z - 8) ** 2) < 30, method=method)
    assert len(result.faces) > 100, method
verts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
faces = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
assert len(remesh_mesh(verts, faces, resolution=16).faces) > 10
print("torch" in sys.modules)
"""
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip() == "False"


def test_automatic_threads_come_back_after_a_one_thread_run():
    """threads=None means every core this process may use, whatever an earlier call asked."""
    from agndc_core.pipeline import remesh
    from agndc_core.runtime.parallel import default_threads

    grid = np.pad(np.ones((5, 6, 4), dtype=bool), 2)
    before = get_threads()
    try:
        remesh(grid, method="agndc", threads=1)
        assert get_threads() == 1
        remesh(grid, method="agndc")
        assert get_threads() == default_threads()
    finally:
        set_threads(before)


def test_vertices_alone_equal_the_full_prediction():
    """edges=False (what the pipeline asks for) keeps the vertex channels only: the same
    vertices, no edge probabilities."""
    network = load_network(default_checkpoint_path("agndc"))
    lattice = np.pad(cad_lattice(32, 8), ((3, 0), (0, 2), (1, 1)))
    vertex, edge = predict_lattice(network, lattice)
    alone, none = predict_lattice(network, lattice, edges=False)
    assert none is None and edge is not None
    np.testing.assert_array_equal(alone, vertex)
