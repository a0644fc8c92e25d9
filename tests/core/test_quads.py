"""Quad output (quads.py): the triangles of each dual-contouring quad joined back where planar
and convex; the polygons cover exactly the triangle mesh's closed surface."""

import numpy as np
import pytest

from agndc_core.checkpoint import default_checkpoint_path
from agndc_core.contour import dual_contour
from agndc_core.grid import VoxelGrid, crossed_edges, pad_to_lattice
from agndc_core.meshcheck import topology_violations
from agndc_core.pipeline import CHECKPOINT_NAMES, remesh, remesh_mesh
from agndc_core.quads import QuadMesh, join_quads, polygon_triangles, quad_mesh, triangulate
from agndc_core.surfacenets import surface_nets_lattice
from agndc_core.tolerances import tol
from conftest import sphere

HAS_AGNDC = default_checkpoint_path(CHECKPOINT_NAMES["agndc"]).exists()
needs_agndc = pytest.mark.skipif(not HAS_AGNDC, reason="no shipped weights")


def box_grid():
    occupancy = np.zeros((30, 24, 20), bool)
    occupancy[2:28, 2:22, 2:18] = True
    return occupancy


def l_grid():
    """An axis-aligned L: a slab with a block standing on one end."""
    occupancy = np.zeros((36, 20, 28), bool)
    occupancy[2:34, 2:18, 2:10] = True
    occupancy[2:12, 2:18, 10:26] = True
    return occupancy


def canonical(faces) -> np.ndarray:
    """Triangles rotated to start at their smallest index (winding kept), rows sorted."""
    faces = np.asarray(faces).reshape(-1, 3)
    shift = np.argmin(faces, axis=1)[:, None]
    rolled = faces[np.arange(len(faces))[:, None], (shift + np.arange(3)) % 3]
    return rolled[np.lexsort(rolled.T[::-1])]


def polygon_edge_counts(polygons: QuadMesh):
    """(undirected uses per edge, directed uses per half edge) over quads and triangles."""
    half = np.concatenate([polygons.quads[:, [0, 1, 1, 2, 2, 3, 3, 0]].reshape(-1, 2),
                           polygons.triangles[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)])
    _, undirected = np.unique(np.sort(half, axis=1), axis=0, return_counts=True)
    _, directed = np.unique(half, axis=0, return_counts=True)
    return undirected, directed


def quad_offsets(vertices, quads) -> np.ndarray:
    """(Q,) largest distance of a quad's vertex from the plane of the triangle opposite it
    (the quad split along its diagonal b - d), in the units of ``vertices``."""
    a, b, c, d = (vertices[quads[:, k]] for k in range(4))
    n1, n2 = np.cross(b - a, d - a), np.cross(d - c, b - c)
    off1 = np.abs(np.einsum("ij,ij->i", c - a, n1)) / np.linalg.norm(n1, axis=1)
    off2 = np.abs(np.einsum("ij,ij->i", a - c, n2)) / np.linalg.norm(n2, axis=1)
    return np.maximum(off1, off2)


def quad_turns(vertices, quads) -> np.ndarray:
    """(Q, 4) sine of each corner's turn, signed along the quad's mean normal."""
    corners = vertices[quads]  # (Q, 4, 3)
    out = np.roll(corners, -1, axis=1) - corners
    into = np.roll(out, 1, axis=1)
    normal = np.cross(corners[:, 2] - corners[:, 0], corners[:, 3] - corners[:, 1])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    turn = np.einsum("qkj,qj->qk", np.cross(into, out), normal)
    return turn / (np.linalg.norm(into, axis=2) * np.linalg.norm(out, axis=2))


def assert_same_closed_surface(result, polygons: QuadMesh):
    """Quads + triangles: every edge in two polygons, one direction each; triangulated, the
    very triangles of the result; every vertex used."""
    undirected, directed = polygon_edge_counts(polygons)
    assert np.all(undirected == 2) and np.all(directed == 1)
    assert 2 * len(polygons.quads) + len(polygons.triangles) == len(result.faces)
    back = polygon_triangles(polygons)
    np.testing.assert_array_equal(canonical(back), canonical(result.faces))
    assert not any(topology_violations(result.vertices, back).values())
    used = np.unique(np.concatenate([polygons.quads.ravel(), polygons.triangles.ravel()]))
    np.testing.assert_array_equal(used, np.arange(len(result.vertices)))


MIRROR = np.diag([-0.5, 0.5, 0.5, 1.0])


@pytest.mark.parametrize("method", ["surfacenets", "agndc"])
@pytest.mark.parametrize("shape", ["box", "l_shape", "mirrored_box"])
def test_box_and_l_shape_give_closed_manifolds_of_quads(method, shape):
    if method == "agndc" and not HAS_AGNDC:
        pytest.skip("no shipped weights")
    occupancy = l_grid() if shape == "l_shape" else box_grid()
    affine = MIRROR if shape == "mirrored_box" else np.eye(4)
    result = remesh(VoxelGrid(occupancy, affine=affine), method=method)
    polygons = result.polygons()
    assert polygons.quad_fraction >= 0.9, polygons.quad_fraction
    assert_same_closed_surface(result, polygons)
    index = result.grid.world_to_index(result.vertices)
    assert quad_offsets(index, polygons.quads).max() <= tol.quad_planar + 1e-9
    assert quad_turns(index, polygons.quads).min() > 0  # convex, wound like the triangles


@pytest.mark.parametrize("method", ["sharp", "surfacenets", "agndc"])
def test_sphere_quads_are_planar_and_convex(method):
    if method == "agndc" and not HAS_AGNDC:
        pytest.skip("no shipped weights")
    mesh = sphere()
    result = remesh_mesh(mesh.vertices, mesh.faces, resolution=32, method=method)
    polygons = result.polygons()
    assert_same_closed_surface(result, polygons)
    index = result.grid.world_to_index(result.vertices)
    offsets = quad_offsets(index, polygons.quads)
    assert offsets.max() <= tol.quad_planar + 1e-9
    assert quad_turns(index, polygons.quads).min() > np.sin(np.radians(1)) * 0.99
    # the joined quads are not a tolerance of zero: curved quads within it are joined
    assert len(polygons.quads) > 0.2 * len(result.faces) / 2
    assert np.percentile(offsets, 90) > 0.1 * tol.quad_planar
    tighter = quad_mesh(result, tolerance=tol.quad_planar / 5)
    assert len(tighter.quads) < len(polygons.quads)


def test_marching_cubes_gives_triangles_only():
    result = remesh(box_grid(), method="mc")
    polygons = result.polygons()
    assert result.face_quads is None and len(polygons.quads) == 0
    np.testing.assert_array_equal(polygons.triangles, result.faces)


SQUARE = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=float)


@pytest.mark.parametrize("change, joined", [
    (None, True),
    ("lift 0.04", True),  # within 0.05 of the other triangle's plane
    ("lift 0.08", False),
    ("dart", False),  # corner 2 pushed inside: concave
    ("straight", False),  # corner 2 on the line of its neighbours
    ("same winding", False),
    ("groups", False),
])
def test_join_quads_joins_only_safe_pairs(change, joined):
    vertices = SQUARE.copy()
    faces = np.array([[0, 1, 3], [1, 2, 3]])  # split along 1 - 3
    groups = None
    if change and change.startswith("lift"):
        vertices[2, 2] = float(change.split()[1])
    elif change == "dart":
        vertices[2] = [0.3, 0.3, 0]
    elif change == "straight":  # corner 1 between 0 and 2 on one line
        vertices = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [1, 1, 0]], dtype=float)
    elif change == "same winding":
        faces = np.array([[0, 1, 3], [1, 3, 2]])
    elif change == "groups":
        groups = np.array([0, 1])
    out = join_quads(vertices, faces, np.array([7, 7]), groups=groups)
    assert len(out.quads) == int(joined) and len(out.triangles) == 2 * (1 - int(joined))
    if joined:
        np.testing.assert_array_equal(out.quads, [[0, 1, 2, 3]])
        np.testing.assert_array_equal(canonical(triangulate(out.quads)), canonical(faces))
        np.testing.assert_array_equal(out.quad_faces, [[0, 1]])


def test_join_quads_leaves_odd_ids_and_unmarked_faces():
    vertices = np.concatenate([SQUARE, SQUARE + [0, 0, 1]])
    faces = np.array([[0, 1, 3], [1, 2, 3], [4, 5, 7], [5, 6, 7], [4, 6, 7]])
    out = join_quads(vertices, faces, np.array([-1, -1, 3, 3, 3]))
    assert len(out.quads) == 0
    np.testing.assert_array_equal(out.triangle_faces, np.arange(5))


def test_join_quads_of_an_empty_mesh():
    out = join_quads(np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64), np.zeros(0, dtype=int))
    assert out.quads.shape == (0, 4) and out.triangles.shape == (0, 3)
    assert out.polygon_count == 0 and out.quad_fraction == 0.0


def noise_lattice(seed=3, shape=(14, 12, 10)):
    occupancy = np.random.default_rng(seed).random(shape) < 0.3
    return pad_to_lattice(occupancy)


def test_dual_contour_reports_the_quad_of_each_face():
    lattice = noise_lattice()
    edge = crossed_edges(lattice)
    vertex = surface_nets_lattice(lattice)
    vertices, faces = dual_contour(vertex, edge, lattice)
    same_vertices, same_faces, face_quads = dual_contour(vertex, edge, lattice, face_quads=True)
    np.testing.assert_array_equal(faces, same_faces)
    np.testing.assert_array_equal(vertices, same_vertices)
    counts = np.bincount(face_quads)
    assert counts.min() >= 2 and counts.max() <= 3
    assert np.count_nonzero(counts == 3) > 0  # noise has tube faces
    # each face's corners are vertices of its quad's 4 cells: the quad's faces share an edge
    out = join_quads(vertices, faces, face_quads, tolerance=np.inf)
    assert len(out.quads) == np.count_nonzero(counts == 2)


@pytest.mark.parametrize("options", [dict(min_component_faces=40), dict(merge_vertices=True),
                                     dict(inside=None)])
def test_face_quads_follow_dropped_and_merged_faces(options):
    lattice = noise_lattice(seed=5)
    edge = crossed_edges(lattice)
    vertex = np.clip(surface_nets_lattice(lattice), 0.0, 1.0)
    inside = options.pop("inside", lattice)
    vertices, faces = dual_contour(vertex, edge, inside, **options)
    _, same_faces, face_quads = dual_contour(vertex, edge, inside, face_quads=True, **options)
    np.testing.assert_array_equal(faces, same_faces)
    assert len(face_quads) == len(faces)
    out = join_quads(vertices, faces, face_quads, tolerance=np.inf)
    shared = np.array([len(set(a) & set(b)) for a, b in faces[out.quad_faces]])
    assert len(out.quads) > 0 and np.all(shared == 2)


def read_obj_polygons(path):
    vertices, polygons = [], []
    for line in path.read_text().splitlines():
        if line.startswith("v "):
            vertices.append([float(x) for x in line.split()[1:]])
        elif line.startswith("f "):
            polygons.append([int(x) - 1 for x in line.split()[1:]])
    return np.array(vertices), polygons


@pytest.mark.parametrize("ext", [".obj", ".ply"])
def test_quad_files_round_trip(tmp_path, ext):
    from agndc_core.gridio import load_mesh, save_mesh

    result = remesh(l_grid(), method="surfacenets")
    polygons = result.polygons()
    path = tmp_path / f"l{ext}"
    save_mesh(result.vertices, result.faces, path, polygons=polygons)
    if ext == ".obj":
        vertices, faces = read_obj_polygons(path)
        np.testing.assert_allclose(vertices, result.vertices, atol=1e-8)
        quads = np.array([f for f in faces if len(f) == 4])
        triangles = np.array([f for f in faces if len(f) == 3])
        np.testing.assert_array_equal(quads, polygons.quads)
        np.testing.assert_array_equal(triangles, polygons.triangles)
    else:
        import trimesh

        loaded = trimesh.load(path, process=False)
        np.testing.assert_allclose(loaded.vertices, result.vertices, atol=1e-5)
    # any reader that triangulates (trimesh here) gets the same closed surface back
    vertices, faces = load_mesh(path)
    assert len(vertices) == len(result.vertices) and len(faces) == len(result.faces)
    assert not any(topology_violations(vertices, faces).values())
    assert volume(vertices, faces) == pytest.approx(volume(result.vertices, result.faces), 1e-5)


def volume(vertices, faces) -> float:
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6)


def test_stl_with_polygons_writes_triangles(tmp_path):
    from agndc_core.gridio import load_mesh, save_mesh

    result = remesh(box_grid(), method="surfacenets")
    save_mesh(result.vertices, result.faces, tmp_path / "b.stl", polygons=result.polygons())
    _, faces = load_mesh(tmp_path / "b.stl")
    assert len(faces) == len(result.faces)


def test_cli_quads_writes_quads(tmp_path, capsys):
    from agndc_core.cli import main

    np.save(tmp_path / "l.npy", l_grid())
    out = tmp_path / "l.obj"
    assert main(["remesh", str(tmp_path / "l.npy"), "-o", str(out), "--method", "surfacenets",
                 "--quads"]) == 0
    _, faces = read_obj_polygons(out)
    sizes = np.bincount([len(f) for f in faces], minlength=5)
    assert sizes[4] >= 0.9 * len(faces)
    assert "% quads" in capsys.readouterr().out


def test_a_decimated_mesh_is_triangles_only():
    """Low poly's faces come from no dual-contouring quad: the result has no quad ids, and
    polygons() gives its triangles unchanged."""
    from agndc_core.pipeline import remesh

    occupancy = np.zeros((14, 14, 14), dtype=bool)
    occupancy[3:11, 3:11, 3:11] = True
    result = remesh(occupancy, method="surfacenets", target_faces=50)
    assert result.face_quads is None
    polygons = result.polygons()
    assert len(polygons.quads) == 0 and len(polygons.triangles) == len(result.faces)
