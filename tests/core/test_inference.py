"""predict_lattice: shapes and ranges, band vs dense, tiling, progress and cancellation."""

import numpy as np
import pytest
import torch

from agndc_core.errors import AGNDCError, CancelledError, GridError
from agndc_core.grid import pad_to_lattice
from agndc_core.inference import BAND_TOLERANCE, TILE_TOLERANCE, predict_lattice, trained_window
from agndc_core.labels import crossed_edges, surface_cells
from agndc_core.nn import AGNDCCascade, AGNDCConfig
from agndc_core.runtime import Network
from conftest import randomise_outputs


def lattice_of(shape, centre, radius, box):
    """A sphere fused with a box in a padded lattice of ``shape``."""
    x, y, z = np.meshgrid(*[np.arange(n) for n in shape], indexing="ij")
    sphere = sum((a - c) ** 2 for a, c in zip((x, y, z), centre)) < radius ** 2
    (x0, x1), (y0, y1), (z0, z1) = box
    return sphere | ((x >= x0) & (x < x1) & (y >= y0) & (y < y1) & (z >= z0) & (z < z1))


@pytest.fixture(scope="module")
def torch_net():
    torch.manual_seed(0)
    return randomise_outputs(AGNDCCascade(AGNDCConfig(width=8))).eval()


@pytest.fixture(scope="module", params=["torch", "numpy"])
def net(request, torch_net):
    """The same network in both runtimes: every behaviour below holds for each."""
    return torch_net if request.param == "torch" else Network.from_torch(torch_net)


def test_outputs_shapes_ranges_non_multiple_sides(net):
    lattice = lattice_of((23, 18, 13), (10, 9, 6), 5, ((12, 20), (3, 9), (4, 10)))
    vertex, edge = predict_lattice(net, lattice)
    assert vertex.shape == edge.shape == (23, 18, 13, 3)
    assert vertex.dtype == edge.dtype == np.float32
    assert vertex.min() >= 0 and vertex.max() <= 1 and edge.min() >= 0 and edge.max() <= 1


def test_band_matches_dense_where_the_band_covers(net, torch_net):
    lattice = lattice_of((24, 20, 16), (10, 9, 7), 5, ((12, 20), (3, 9), (4, 12)))
    dense = predict_lattice(torch_net, lattice, mode="dense")
    band = predict_lattice(net, lattice, band_radius=40)
    surface = surface_cells(crossed_edges(lattice))
    for d, b in zip(dense, band):
        np.testing.assert_allclose(b[surface], d[surface], atol=BAND_TOLERANCE)


def test_band_converges_to_dense_as_the_radius_grows(torch_net):
    """For densely trained weights the band is an approximation. Random He-initialised weights
    are a harsh case (their receptive field is not local): the gap on surface cells shrinks from
    ~1/3 of the outputs' spread at radius 4 to ~1/100 at radius 8."""
    lattice = lattice_of((32, 32, 24), (14, 15, 11), 6, ((16, 24), (6, 14), (10, 18)))
    surface = surface_cells(crossed_edges(lattice))
    net = torch_net
    with torch.inference_mode():
        dense = net(torch.from_numpy(lattice)[None])[0][0].permute(1, 2, 3, 0)[surface]
        gaps = [float((net.forward_band(lattice, r)[0][surface] - dense).abs().mean())
                for r in (4, 6, 8)]
    spread = float(dense.std(0).mean())
    assert gaps[0] > gaps[1] > gaps[2]
    assert gaps[2] < 0.05 * spread


def test_tiled_equals_untiled_without_seams(net):
    # long along x so the 16-point tiles' 24-point halos are cut off inside the lattice
    lattice = lattice_of((80, 24, 24), (30, 11, 12), 8, ((44, 70), (4, 18), (6, 16)))
    whole = predict_lattice(net, lattice, tile=0)
    tiled = predict_lattice(net, lattice, tile=16)
    for w, t in zip(whole, tiled):
        np.testing.assert_allclose(t, w, atol=TILE_TOLERANCE)


def test_progress_and_cancel(net):
    lattice = lattice_of((16, 16, 16), (8, 8, 8), 4, ((0, 0), (0, 0), (0, 0)))
    calls = []
    predict_lattice(net, lattice, progress=lambda f, m: calls.append((f, m)))
    fractions = [f for f, _ in calls]
    assert fractions == sorted(fractions) and fractions[-1] == 1.0

    class Cancel:
        def is_set(self):
            return True

    with pytest.raises(CancelledError):
        predict_lattice(net, lattice, cancel=Cancel())
    assert issubclass(CancelledError, AGNDCError)


def test_cancel_is_checked_inside_the_network(net):
    """Not only between tiles and scales (4 checks here): on every torch call of the network,
    so a long single tile stops at once."""
    lattice = lattice_of((24, 24, 24), (12, 12, 12), 6, ((0, 0), (0, 0), (0, 0)))

    class CancelOnCall:
        calls = 0

        def is_set(self):
            self.calls += 1
            return self.calls >= 60

    cancel = CancelOnCall()
    with pytest.raises(CancelledError):
        predict_lattice(net, lattice, cancel=cancel, tile=0)
    assert cancel.calls == 60  # raised on the first check that saw the event set


def test_progress_inside_a_tile(net, monkeypatch):
    import agndc_core.inference as inference

    monkeypatch.setattr(inference, "PROGRESS_INTERVAL", 0.0)
    lattice = lattice_of((24, 24, 24), (12, 12, 12), 6, ((0, 0), (0, 0), (0, 0)))
    calls = []
    predict_lattice(net, lattice, tile=0, progress=lambda f, m: calls.append(f))
    assert len(calls) > 100  # 3 scales in one tile each: far more reports than tiles
    assert calls == sorted(calls) and 0.0 <= calls[0] and calls[-1] == 1.0
    assert len(set(calls)) > 10  # the bar moves within the scales, not only between them


def test_rejects_bad_input(net):
    with pytest.raises(GridError):
        predict_lattice(net, np.zeros((4, 4)))
    with pytest.raises(GridError):
        predict_lattice(net, np.full((4, 4, 4), 2))
    with pytest.raises(AGNDCError, match="mode"):
        predict_lattice(net, np.zeros((4, 4, 4), bool), mode="fast")


def test_uniform_lattices_are_all_far_field(net):
    """No surface: every point is far field, periodic with the finest scale's period."""
    period = net.torus_periods[0]
    for value in (False, True):
        vertex, edge = predict_lattice(net, np.full((24, 16, 16), value))
        for out in (vertex, edge):
            assert np.isfinite(out).all()
            np.testing.assert_array_equal(out[period:], out[:-period])
            np.testing.assert_array_equal(out[:, period:], out[:, :-period])


def _framed_shape():
    """A sphere fused with a box, framed exactly as voxelising frames it (pad_to_lattice of the
    occupied voxels plus one empty voxel on every side)."""
    shape = lattice_of((13, 11, 9), (6, 5, 4), 4, ((7, 13), (2, 6), (3, 9)))
    occupied = np.argwhere(shape)
    lo, hi = occupied.min(0), occupied.max(0) + 1
    core = shape[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]]
    return pad_to_lattice(np.pad(core, 1))


def test_a_voxelised_shape_is_already_in_its_trained_window():
    lattice = _framed_shape()
    assert trained_window(lattice) is None
    assert trained_window(np.zeros((8, 8, 8), bool)) is None
    touching = lattice.copy()
    touching[0, 5, 5] = True  # outside the lattice is then not known to be empty
    assert trained_window(touching) is None


def test_extra_empty_margins_are_framed_away():
    lattice = _framed_shape()
    extra = np.pad(lattice, ((3, 5), (1, 0), (0, 7)))
    start, window = trained_window(extra)
    np.testing.assert_array_equal(start, [3, 1, 0])
    np.testing.assert_array_equal(window, lattice)


def test_the_prediction_does_not_depend_on_the_empty_margins(net):
    """The network learned shapes framed as voxelising frames them; a grid with more (or less)
    empty space around its shape gets exactly the same vertices."""
    lattice = _framed_shape()
    vertex, edge = predict_lattice(net, lattice)
    extra = np.pad(lattice, ((3, 5), (1, 0), (0, 7)))
    inner = (slice(3, 3 + lattice.shape[0]), slice(1, 1 + lattice.shape[1]),
             slice(0, lattice.shape[2]))
    for ours, theirs in zip((vertex, edge), predict_lattice(net, extra)):
        np.testing.assert_array_equal(theirs[inner], ours)
    # less margin than voxelising leaves: the window reaches beyond the lattice
    tight = lattice[1:, :, :]
    cells = surface_cells(crossed_edges(tight))
    np.testing.assert_array_equal(predict_lattice(net, tight)[0][cells], vertex[1:][cells])
    # the raw network does see the margin (what canonical framing removes)
    raw = predict_lattice(net, extra, canonical=False)[0][inner]
    assert np.abs(raw - vertex)[surface_cells(crossed_edges(lattice))].max() > 1e-3


def test_the_network_sees_empty_points_past_the_high_end(net):
    """``high_margin``: the network runs on the lattice with that many empty points after its
    high end, exactly as on a lattice that had them, cropped back; an axis whose last layer is
    occupied gets none (what lies beyond it is not known to be empty)."""
    lattice = _framed_shape()
    own = tuple(slice(0, n) for n in lattice.shape)
    vertex, edge = predict_lattice(net, lattice, high_margin=4)
    wide = np.pad(lattice, [(0, 4)] * 3)
    for ours, theirs in zip((vertex, edge), predict_lattice(net, wide, canonical=False)):
        np.testing.assert_array_equal(theirs[own], ours)
    cells = surface_cells(crossed_edges(lattice))
    assert np.abs(predict_lattice(net, lattice)[0] - vertex)[cells].max() > 1e-3
    cut = lattice[:np.nonzero(lattice.any(axis=(1, 2)))[0][-1]]  # cut through the shape in x
    assert np.take(cut, -1, 0).any()
    wide_yz = np.pad(cut, [(0, 0)] + [(0, 4)] * 2)
    np.testing.assert_array_equal(
        predict_lattice(net, wide_yz, canonical=False)[0][:, :cut.shape[1], :cut.shape[2]],
        predict_lattice(net, cut, canonical=False, high_margin=4)[0])


def test_each_learned_method_runs_with_its_own_high_margin():
    """The pipeline runs AGNDC with its high margin and UNDC with none (methods.Method)."""
    from agndc_core.methods import BY_NAME
    from agndc_core.pipeline import _default_checkpoint, _predict, load_model

    lattice = _framed_shape()
    assert BY_NAME["agndc"].high_margin == 4 and BY_NAME["undc"].high_margin == 0
    for name in ("agndc", "undc"):
        ours = _predict(name, lattice, None, None, 1, "cpu", None, None, None)
        model = load_model(_default_checkpoint(name))
        expected = predict_lattice(model, lattice, edges=False,
                                   high_margin=BY_NAME[name].high_margin)[0]
        np.testing.assert_array_equal(ours, expected)


def test_remesh_of_a_grid_ignores_its_empty_margins():
    """The same voxels with 3 more empty layers in front give the same mesh, 3 voxels along
    (the shipped network, through pipeline.remesh; remesh_mesh's grids are voxelised already)."""
    from agndc_core.pipeline import remesh

    x, y, z = np.meshgrid(*[np.arange(14)] * 3, indexing="ij")
    shape = ((x - 6.3) ** 2 + (y - 7.1) ** 2 + (z - 6.6) ** 2 < 25) | (
        (x >= 3) & (x < 12) & (y >= 2) & (y < 7) & (z >= 4) & (z < 10))
    tight = remesh(shape, method="agndc", threads=1)
    loose = remesh(np.pad(shape, ((3, 0), (3, 0), (3, 0))), method="agndc", threads=1)
    np.testing.assert_array_equal(loose.faces, tight.faces)
    np.testing.assert_allclose(loose.vertices - 3.0, tight.vertices, atol=1e-5)
    raw = remesh(np.pad(shape, ((3, 0), (3, 0), (3, 0))), method="agndc", threads=1,
                 reframe=False)
    assert np.abs(raw.vertices - 3.0 - tight.vertices).max() > 1e-3
