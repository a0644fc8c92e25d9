"""research/headroom_bound.py's substitutions: the network's depth replaces the ground truth only
along the normal of exactly axis-aligned faces (the converse, the truth there and the network
elsewhere), and its error scale interpolates between the two."""


import numpy as np

from agndc_core.grid import pad_to_lattice
from agndc_core.labels import make_labels
from agndc_core.surfacenets import surface_nets_lattice
from agndc_core.tolerances import tol
from agndc_core.voxelize import voxelize
from conftest import box, research_script, rotation


def _script():
    return research_script("headroom_bound")


def _variants(mesh, network_of):
    grid = voxelize(mesh.vertices, mesh.faces, 20)
    lattice = pad_to_lattice(grid.occupancy)
    labels = make_labels(mesh.vertices, mesh.faces, grid, levels=0)[0]
    network = network_of(lattice, labels)
    return labels, network, _script().variants(labels, network, lattice, [0.5])


def test_a_rotated_box_has_no_depth_to_substitute():
    """No face is axis-aligned: every ground-truth substitution is the oracle itself."""
    turn = rotation(np.radians(20), [1, 0, 0]) @ rotation(np.radians(35), [0, 1, 0])
    labels, network, out = _variants(box(transform=turn),
                                     lambda lattice, _: surface_nets_lattice(lattice))
    for name in ("network_depth", "network_depth_0.5", "oracle_binary"):
        np.testing.assert_array_equal(out[name], labels.vertex, err_msg=name)
    np.testing.assert_array_equal(out["true_depth"], network)


def test_an_axis_aligned_box_takes_the_network_depth_along_the_normal_only():
    """With surface nets standing in for the network, network_depth is oracle_binary; with a
    network one voxel-tenth off everywhere, only the coordinates along face normals move, and
    half as far at alpha 0.5."""
    labels, _, out = _variants(box(), lambda lattice, _: surface_nets_lattice(lattice))
    np.testing.assert_array_equal(out["network_depth"], out["oracle_binary"])

    labels, network, out = _variants(box(), lambda _, labels: labels.vertex + 0.1)
    moved = out["network_depth"] != labels.vertex  # (X, Y, Z, 3)
    aligned = labels.quadric[..., :3] > tol.axis_aligned  # the labels' own test
    assert moved.any() and not (moved & ~aligned).any()
    np.testing.assert_allclose(out["network_depth"][moved], network[moved], atol=1e-6)
    half = out["network_depth_0.5"] - labels.vertex
    np.testing.assert_allclose(half[moved], 0.05, atol=1e-6)
    # the converse keeps the network everywhere but there
    np.testing.assert_array_equal(out["true_depth"] != network, moved)


def test_generated_shapes_are_held_out_seeds_named_by_family():
    """--generated N scores the generator's own shapes from the held-out seed range."""
    import argparse

    from agndc_core.study.shapes import shape_family

    script = _script()
    args = argparse.Namespace(generated=2, dev="unused", limit=None)
    found = list(script.shapes(args))
    assert [name for name, *_ in found] == ["seed7000001", "seed7000002"]
    assert [kind for _, kind, *_ in found] == [shape_family(7_000_001), shape_family(7_000_002)]
    assert all(len(v) and len(f) for *_, v, f in found)
