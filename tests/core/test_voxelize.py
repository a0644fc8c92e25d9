import numpy as np
import pytest

from agndc_core import MeshError
from agndc_core.voxelize import voxelize
from conftest import box, cylinder_with_hole, rotation, sphere


def test_axis_aligned_box_faces_within_a_voxel():
    mesh = box((1.0, 0.5, 0.3))
    grid = voxelize(mesh.vertices, mesh.faces, 40)
    centres = grid.index_to_world(np.argwhere(grid.occupancy))
    h = grid.voxel_size[0]
    # occupied voxel centres stay inside the box, and reach to within one voxel of each face
    assert np.all(np.abs(centres) <= np.array([0.5, 0.25, 0.15]) + 1e-9)
    assert np.all(np.abs(centres).max(axis=0) >= np.array([0.5, 0.25, 0.15]) - h)


@pytest.mark.parametrize("make", [lambda: box(transform=rotation(0.5, [1, 1, 0])),
                                  lambda: sphere(), cylinder_with_hole])
def test_volume_matches(make):
    mesh = make()
    grid = voxelize(mesh.vertices, mesh.faces, 64)
    volume = grid.occupancy.sum() * grid.voxel_size.prod()
    assert abs(volume - mesh.volume) / mesh.volume < 0.02


def test_rules_agree_on_closed_mesh_and_holes_are_outvoted():
    mesh = sphere(subdivisions=4)
    closed = voxelize(mesh.vertices, mesh.faces, 48).occupancy
    parity = voxelize(mesh.vertices, mesh.faces, 48, rule="parity").occupancy
    assert np.array_equal(closed, parity)
    holed = voxelize(mesh.vertices, mesh.faces[20:], 48).occupancy
    assert (holed != closed).sum() < 0.01 * closed.sum()


def test_inverted_mesh_still_solid():
    mesh = sphere(subdivisions=3)
    grid = voxelize(mesh.vertices, mesh.faces[:, ::-1], 32)
    ref = voxelize(mesh.vertices, mesh.faces, 32)
    assert np.array_equal(grid.occupancy, ref.occupancy)


def test_non_cubic_shape_and_margin():
    mesh = box((1.0, 0.2, 0.1))
    grid = voxelize(mesh.vertices, mesh.faces, 50)
    assert grid.shape[0] == 50 and grid.shape[1] < 20
    for axis in range(3):
        assert not grid.occupancy.take(0, axis=axis).any()


@pytest.mark.parametrize("vertices, faces, message", [
    (np.zeros((3, 3)), np.zeros((0, 3), int), "no faces"),
    (np.zeros((3, 3)), np.array([[0, 1, 2]]), "zero extent"),
    (np.array([[0, 0, 0], [1, 0, 0], [np.nan, 1, 0]]), np.array([[0, 1, 2]]), "non-finite"),
    (np.eye(3), np.array([[0, 1, 5]]), "outside"),
])
def test_bad_meshes_are_named(vertices, faces, message):
    with pytest.raises(MeshError, match=message):
        voxelize(vertices, faces, 16)


@pytest.mark.parametrize("stray", [(50.0, -3.0, 7.0), (np.nan, 0.0, np.inf)])
def test_vertices_no_face_uses_are_ignored(stray):
    mesh = box((1.0, 0.5, 0.3))
    reference = voxelize(mesh.vertices, mesh.faces, 32)
    grid = voxelize(np.vstack([mesh.vertices, stray]), mesh.faces, 32)
    assert np.array_equal(grid.occupancy, reference.occupancy)
    assert np.allclose(grid.affine, reference.affine)
    assert np.allclose(grid.source_bounds, [[-0.5, -0.25, -0.15], [0.5, 0.25, 0.15]])


def test_matches_trimesh_contains_on_a_small_grid():
    mesh = box(transform=rotation(0.3, [0, 1, 1]))
    grid = voxelize(mesh.vertices, mesh.faces, 20)
    points = grid.index_to_world(np.argwhere(np.ones(grid.shape, bool)))
    reference = mesh.contains(points).reshape(grid.shape)
    assert (reference != grid.occupancy).sum() <= 2  # points on the surface may differ


@pytest.mark.parametrize("rule", ["winding", "parity"])
def test_ray_casting_in_chunks_gives_the_same_grid_and_checks_between_them(monkeypatch, rule):
    """The winding test's edges, the triangles' column ranges and the candidate (triangle,
    column) pairs go in chunks, with ``check`` called before each: any chunk sizes give the
    same occupancy, and a check that raises stops the work."""
    from agndc_core import voxelize as module

    mesh = cylinder_with_hole()
    whole = voxelize(mesh.vertices, mesh.faces, 48, rule=rule).occupancy
    monkeypatch.setattr(module, "PAIR_CHUNK", 257)
    monkeypatch.setattr(module, "TRIANGLE_CHUNK", 100)
    monkeypatch.setattr(module, "EDGE_CHUNK", 300)
    calls = []
    chunked = voxelize(mesh.vertices, mesh.faces, 48, rule=rule,
                       check=lambda: calls.append(1)).occupancy
    np.testing.assert_array_equal(chunked, whole)
    assert len(calls) > 3 * 10  # several chunks per axis

    def cancel():
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        voxelize(mesh.vertices, mesh.faces, 48, check=cancel)


@pytest.mark.parametrize("edge_chunk", [1 << 21, 300])
def test_winding_rule_test_in_groups_of_edges(monkeypatch, edge_chunk):
    """The winding rule is for closed, consistently oriented meshes: the test runs over groups of
    edges that share their lower vertex (a check between them) and sees a hole, a flipped face
    and a repeated face whatever the group size."""
    from agndc_core import voxelize as module

    monkeypatch.setattr(module, "EDGE_CHUNK", edge_chunk)
    faces = np.asarray(cylinder_with_hole().faces, dtype=np.int64)
    flipped = faces.copy()
    flipped[7] = flipped[7, ::-1]
    calls = []
    assert module._choose_rule(faces, "auto", check=lambda: calls.append(1)) == "winding"
    assert len(calls) > (10 if edge_chunk == 300 else 1)
    for broken in (faces[1:], flipped, np.concatenate([faces, faces[:1]])):
        assert module._choose_rule(broken, "auto") == "parity"
