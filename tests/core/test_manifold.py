"""Every contoured binary grid is a closed, oriented 2-manifold with the expected components.

Connectivity (the rule of ``contour.py`` and of scikit-image's Lorensen table used by ``mc.py``):
inside voxels are 6-connected, outside voxels 18-connected. The expected number of closed surfaces
is computed independently with ``scipy.ndimage.label``: one surface per touching pair (sharing a
lattice edge) of a 6-connected inside region and an 18-connected outside region, on a grid padded
with empty voxels so the outside around it is one region. Surfaces face away from the solid, so
the surface of a cavity (an outside region that does not reach the border) has negative signed
volume: there is exactly one such surface per cavity, every other surface has positive volume.
"""

import time

import numpy as np
import pytest
from scipy import ndimage

from agndc_core import contour
from agndc_core.contour import dual_contour, face_components
from agndc_core.labels import crossed_edges
from agndc_core.mc import marching_cubes_lattice
from agndc_core.meshcheck import topology_violations
from agndc_core.surfacenets import surface_nets_lattice

N_GRIDS = 520
SIX, EIGHTEEN = ndimage.generate_binary_structure(3, 1), ndimage.generate_binary_structure(3, 2)


def random_grids(count=N_GRIDS, seed=14):
    """Seeded padded lattices: sizes 3..24 per axis (mostly small), densities 0.05..0.95."""
    rng = np.random.default_rng(seed)
    for n in range(count):
        high = 25 if n % 10 == 0 else 11
        shape = rng.integers(3, high, size=3)
        density = rng.uniform(0.05, 0.95)
        yield n, np.pad(rng.random(shape) < density, 1)


def component_volumes(vertices, faces) -> np.ndarray:
    """(K,) signed volume of each connected component."""
    if len(faces) == 0:
        return np.zeros(0)
    triangles = vertices[faces]
    volume = np.einsum("ij,ij->i", triangles[:, 0],
                       np.cross(triangles[:, 1], triangles[:, 2])) / 6.0
    return np.bincount(face_components(faces, len(vertices)), volume)


def expected_surfaces(lattice) -> tuple[int, int]:
    """(surfaces, cavities) implied by 6-connected inside and 18-connected outside."""
    inner, _ = ndimage.label(lattice, SIX)
    outer, n_outer = ndimage.label(~lattice, EIGHTEEN)
    pairs = []
    for axis in range(3):
        low = [slice(None)] * 3
        high = [slice(None)] * 3
        low[axis], high[axis] = slice(0, -1), slice(1, None)
        a_in = lattice[tuple(low)]
        crossed = a_in != lattice[tuple(high)]
        region_in = np.where(a_in, inner[tuple(low)], inner[tuple(high)])[crossed]
        region_out = np.where(a_in, outer[tuple(high)], outer[tuple(low)])[crossed]
        pairs.append(region_in.astype(np.int64) * (n_outer + 1) + region_out)
    surfaces = len(np.unique(np.concatenate(pairs)))
    return surfaces, n_outer - 1  # the padded border is one outside region, the rest cavities


def check_mesh(vertices, faces, lattice, *, signs: bool) -> dict:
    """All defect counts of one output, including components and (optionally) volume signs."""
    found = topology_violations(vertices, faces)
    surfaces, cavities = expected_surfaces(lattice)
    volumes = component_volumes(vertices, faces)
    found["wrong_component_count"] = int(len(volumes) != surfaces)
    if signs:
        bad_sign = np.sum(volumes < 0) != cavities or np.sum(volumes > 0) != surfaces - cavities
        found["wrong_volume_signs"] = int(bad_sign)
    return found


def run_property(method: str) -> tuple[int, dict]:
    totals: dict = {}
    grids = 0
    for n, lattice in random_grids():
        edge = crossed_edges(lattice)
        if method == "mc":
            meshes = [(marching_cubes_lattice(lattice), True)]
        else:
            rng = np.random.default_rng(n)
            random = rng.random(lattice.shape + (3,))
            meshes = [(dual_contour(surface_nets_lattice(lattice), edge, lattice), True),
                      # arbitrary positions keep the topology; only geometry (signs) may flip
                      (dual_contour(random, edge, lattice), False)]
        for (vertices, faces), signs in meshes:
            for key, value in check_mesh(vertices, faces, lattice, signs=signs).items():
                totals[key] = totals.get(key, 0) + value
        grids += 1
    return grids, totals


@pytest.mark.slow
@pytest.mark.parametrize("method", ["dual_contour", "mc"])
def test_random_grids_give_closed_oriented_manifolds(method):
    start = time.perf_counter()
    grids, totals = run_property(method)
    print(f"{method}: {grids} grids in {time.perf_counter() - start:.1f} s, violations {totals}")
    assert grids >= 500
    assert all(count == 0 for count in totals.values()), totals


def test_patch_table_patches_are_disks():
    """Every patch of every case has exactly one boundary loop, so one vertex can span it.

    Boundary loops are traced independently of ``cell_patches``: on each cell face the crossed
    edges are paired into segments (an ambiguous face pairs the edges at each inside corner).
    """
    face_edges = contour._face_edges()
    for config in range(256):
        patch = contour.PATCH[config]
        inside = [(config >> k) & 1 for k in range(8)]
        label = list(range(12))

        def find(i, label=label):
            while label[i] != i:
                i = label[i]
            return i

        for face, ring in zip(face_edges, contour.CELL_FACES):
            crossed = [e for e in face if patch[e] >= 0]
            if len(crossed) == 2:
                label[find(crossed[0])] = find(crossed[1])
            elif len(crossed) == 4:
                for corner in ring:
                    if inside[corner]:
                        pair = [e for e in face if corner in contour.CELL_EDGES[e]]
                        label[find(pair[0])] = find(pair[1])
        loops = {}
        for e in np.flatnonzero(patch >= 0):
            loops.setdefault(int(patch[e]), set()).add(find(int(e)))
        assert all(len(roots) == 1 for roots in loops.values()), config
        roots = [root for roots in loops.values() for root in roots]
        assert len(set(roots)) == len(roots), config  # distinct patches never share a loop


def test_no_cell_joins_two_faces_at_one_edge():
    """So no triangle of a quad ever holds two tube vertices (``_split_tube_sides``)."""
    face_edges = [set(edges) for edges in contour._face_edges()]
    for config in np.flatnonzero(contour.FACE_JOINED.any(axis=1)):
        joined = np.flatnonzero(contour.FACE_JOINED[config])
        for i in joined:
            for j in joined:
                assert i == j or not (face_edges[i] & face_edges[j]), config


def test_tube_face_gets_two_vertices():
    """Inside corners of a face joined around through both cells: the outside threads a ring."""
    lattice = np.zeros((5, 4, 4), bool)
    for x, y, z in [(0, 0, 0), (0, 1, 1), (1, 0, 0), (1, 1, 0), (1, 1, 1),
                    (-1, 0, 0), (-1, 1, 0), (-1, 1, 1)]:
        lattice[x + 2, y + 1, z + 1] = True
    edge = crossed_edges(lattice)
    vertices, faces = dual_contour(np.full(lattice.shape + (3,), 0.5), edge, lattice)
    assert len(faces) == 2 * edge.sum() + 4  # one triangle of each of the face's 4 quads split
    assert not any(check_mesh(vertices, faces, lattice, signs=True).values())
    # on the face x = 2, halfway between each inside corner and the face centre
    np.testing.assert_array_equal(vertices[-2:], [[2, 1.25, 1.25], [2, 1.75, 1.75]])


def noise_grids(count=300, seed=35):
    """I.i.d. voxel noise at densities 0.2-0.35, every third grid a 3-4-voxel thin slab: many
    isolated voxels and one-voxel bridges, where learned vertices fold most easily."""
    rng = np.random.default_rng(seed)
    for n in range(count):
        shape = rng.integers(4, 34, size=3)
        if n % 3 == 0:
            shape = rng.integers(8, 34, size=3)
            shape[rng.integers(3)] = rng.integers(3, 5)
        yield n, rng.random(shape) < rng.uniform(0.2, 0.35)


@pytest.mark.slow
@pytest.mark.parametrize("method", ["agndc", "undc"])
def test_learned_remesh_of_noise_grids_is_closed_and_outward(method):
    """The whole learned pipeline (network, flat patches, normal filter, fold check) on 300
    noise grids: closed 2-manifolds, the expected components, none inside out."""
    from agndc_core.checkpoint import default_checkpoint_path
    from agndc_core.grid import VoxelGrid, pad_to_lattice
    from agndc_core.pipeline import CHECKPOINT_NAMES, remesh

    if not default_checkpoint_path(CHECKPOINT_NAMES[method]).exists():
        pytest.skip("no shipped weights")
    totals, grids = {}, 0
    for _, occupancy in noise_grids():
        result = remesh(VoxelGrid(occupancy), method=method)
        found = check_mesh(result.vertices, result.faces, pad_to_lattice(occupancy), signs=True)
        for key, value in found.items():
            totals[key] = totals.get(key, 0) + value
        grids += 1
    assert grids == 300 and all(count == 0 for count in totals.values()), totals


def test_a_component_turned_inside_out_takes_the_reference_vertices():
    from agndc_core.contour import restore_folded_components

    tetra = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    faces = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    two = np.concatenate([tetra, tetra + 5.0])
    both = np.concatenate([faces, faces + 4])
    folded = two.copy()
    folded[4:] = tetra * [1, 1, -1] + 5.0  # the second one mirrored: inside out
    folded[:4] += 0.01  # the first moved, still outward: kept as it is
    restored, count = restore_folded_components(folded, both, two)
    assert count == 1
    np.testing.assert_array_equal(restored[4:], two[4:])
    np.testing.assert_array_equal(restored[:4], folded[:4])
    assert restore_folded_components(two, both, two)[1] == 0
    # squashed flat (a lone voxel's faces on one plane): no inside either, restored
    flat = two.copy()
    flat[4:, 2] = 5.0 + 1e-9 * tetra[:, 2]  # still outward, by a hair
    restored, count = restore_folded_components(flat, both, two)
    assert count == 1
    np.testing.assert_array_equal(restored[4:], two[4:])
    shrunk = two.copy()
    shrunk[4:] = 0.3 * tetra + 5.0  # small but a solid: kept
    assert restore_folded_components(shrunk, both, two)[1] == 0
