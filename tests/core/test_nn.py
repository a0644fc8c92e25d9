"""AGNDC networks: config validation, shapes, training step, band evaluation == dense."""

import numpy as np
import pytest
import torch

from agndc_core.errors import ModelError
from agndc_core.inference import BAND_TOLERANCE
from agndc_core.labels import crossed_edges, surface_cells
from agndc_core.nn import AGNDCCascade, AGNDCConfig, AGNDCLoss, undc_baseline
from conftest import randomise_outputs


def blob_lattice(shape=(32, 32, 24)) -> np.ndarray:
    """A sphere fused with a box (a concave crease), padded away from the border."""
    x, y, z = np.meshgrid(*[np.arange(n) for n in shape], indexing="ij")
    sphere = (x - 14) ** 2 + (y - 15) ** 2 + (z - 11) ** 2 < 30
    box = (abs(x - 20) < 4) & (abs(y - 10) < 3) & (abs(z - 14) < 4)
    return sphere | box


def model(seed=0, **kw) -> AGNDCCascade:
    torch.manual_seed(seed)
    return randomise_outputs(AGNDCCascade(AGNDCConfig(width=8, **kw))).eval()


# ---------------------------------------------------------------------- config


def test_config_round_trip_and_presets():
    cfg = AGNDCConfig(width=32, levels=1, use_crpm=False)
    assert AGNDCConfig.from_dict(cfg.to_dict()) == cfg
    base = undc_baseline()
    assert (base.levels, base.use_attention, base.use_snake, base.use_dffm, base.use_crpm) == (
        0, False, False, False, False)


@pytest.mark.parametrize("bad, word", [
    ({"width": 30}, "width"), ({"width": "64"}, "width"), ({"levels": -1}, "levels"),
    ({"window": 3}, "window"), ({"heads": 3}, "heads"), ({"snake_kernel": 8}, "snake_kernel"),
    ({"use_snake": 1}, "use_snake"), ({"band_radius": 0}, "band_radius"),
    ({"colour": "red"}, "colour"),
])
def test_config_rejects_bad_values(bad, word):
    with pytest.raises(ModelError, match=word):
        AGNDCConfig.from_dict({**AGNDCConfig().to_dict(), **bad})


def test_config_from_dict_needs_a_mapping():
    with pytest.raises(ModelError, match="mapping"):
        AGNDCConfig.from_dict([("width", 8)])


# ---------------------------------------------------------------------- dense forward


@pytest.mark.parametrize("kw", [{}, {"levels": 0}, {"use_crpm": False},
                                {"use_dffm": False, "use_crpm": False}, {"levels": 1},
                                {"levels": 0, "use_attention": False, "use_snake": False,
                                 "use_dffm": False, "use_crpm": False}])
def test_output_shapes_every_scale_non_cubic(kw):
    net = model(**kw)
    g = torch.from_numpy(blob_lattice((16, 24, 8)))[None].repeat(2, 1, 1, 1)
    with torch.no_grad():
        preds = net(g)
    assert len(preds) == net.levels + 1
    for s, p in enumerate(preds):
        assert p.shape == (2, 6, 16 >> s, 24 >> s, 8 >> s)
        assert torch.isfinite(p).all()


def test_forward_scale_checks_inputs():
    net = model()
    g = torch.zeros(1, 8, 8, 8)
    with pytest.raises(ModelError, match="needs the prediction"):
        net.forward_scale(0, g)
    with pytest.raises(ModelError, match="coarser prediction"):
        net.forward_scale(0, g, torch.zeros(1, 6, 8, 8, 8))
    with pytest.raises(ModelError, match="multiple of 4"):
        net(torch.zeros(1, 10, 8, 8))


def test_training_step_reaches_every_parameter_and_lambda():
    net = model().train()
    loss_fn = AGNDCLoss()
    lattice = blob_lattice((16, 16, 16))
    g = torch.from_numpy(lattice)[None]
    edge = torch.from_numpy(crossed_edges(lattice))[None]
    surface = torch.from_numpy(surface_cells(crossed_edges(lattice)))[None]
    vertex = torch.rand(1, 16, 16, 16, 3)
    p0 = net(g)[0]
    loss, parts = loss_fn(p0, vertex, edge, surface)
    assert torch.isfinite(loss) and parts["lambda"] == pytest.approx(1.0)
    loss.backward()
    assert loss_fn.t.grad is not None and loss_fn.t.grad != 0
    used = [p for n, p in net.nets[0].named_parameters()]
    assert all(p.grad is not None for p in used)
    assert sum(float(p.grad.abs().sum()) for p in used) > 0


def test_loss_rejects_mismatched_targets():
    with pytest.raises(ModelError, match="loss"):
        AGNDCLoss()(torch.zeros(1, 6, 4, 4, 4), torch.zeros(1, 4, 4, 4, 2),
                    torch.zeros(1, 4, 4, 4, 3), torch.zeros(1, 4, 4, 4))


def test_quadric_floor_adds_the_plain_squared_error():
    """Vertex loss = d^T Q d + floor |d|^2 on surface cells: an error along a face (d _|_ n)
    costs only the floor, one across it costs 1 + floor; floor 0 leaves along-face errors free."""
    pred = torch.zeros(1, 6, 2, 2, 2)
    vertex = torch.zeros(1, 2, 2, 2, 3)
    vertex[..., 0] = 0.3  # the error is along x
    surface = torch.ones(1, 2, 2, 2, dtype=torch.bool)
    edge = torch.zeros(1, 2, 2, 2, 3)
    along = torch.zeros(1, 2, 2, 2, 6)
    along[..., 2] = 1.0  # Q = z z^T: a face of normal z, the error lies in it
    across = torch.zeros(1, 2, 2, 2, 6)
    across[..., 0] = 1.0  # Q = x x^T: the error crosses the face
    for floor in (0.0, 0.1, 1.0):
        loss = AGNDCLoss(train_edges=False, quadric_floor=floor)
        v_along, _ = loss(pred, vertex, edge, surface, quadric=along)
        v_across, _ = loss(pred, vertex, edge, surface, quadric=across)
        assert float(v_along) == pytest.approx(floor * 0.09)
        assert float(v_across) == pytest.approx((1 + floor) * 0.09)
    with pytest.raises(ModelError, match="quadric_floor"):
        AGNDCLoss(quadric_floor=-1.0)


def test_crease_weight_weights_crease_cells_in_the_vertex_mean():
    """With crease weight c, a cell whose quadric holds two faces counts 1 + c min(1, I2 / 0.1)
    in the mean of the vertex loss; flat cells count 1; c = 0 is the plain mean."""
    pred = torch.zeros(1, 6, 2, 1, 1)
    vertex = torch.zeros(1, 2, 1, 1, 3)
    vertex[0, 0, 0, 0, 0] = 0.3  # flat cell: error 0.3 across its face (normal x)
    vertex[0, 1, 0, 0, 0] = 0.5  # crease cell: error 0.5 along x, one of its two normals
    surface = torch.ones(1, 2, 1, 1, dtype=torch.bool)
    edge = torch.zeros(1, 2, 1, 1, 3)
    quadric = torch.zeros(1, 2, 1, 1, 6)
    quadric[0, 0, 0, 0, 0] = 1.0                       # Q = x x^T, I2 = 0
    quadric[0, 1, 0, 0, 0] = quadric[0, 1, 0, 0, 1] = 0.5  # Q = (x x^T + y y^T) / 2, I2 = 0.25
    flat, crease = 0.09, 0.5 * 0.25  # d^T Q d of each cell (floor 0)
    for c in (0.0, 1.0, 4.0):
        loss = AGNDCLoss(train_edges=False, quadric_floor=0.0, crease_weight=c)
        value, _ = loss(pred, vertex, edge, surface, quadric=quadric)
        assert float(value) == pytest.approx((flat + (1 + c) * crease) / (2 + c))
    # a weak crease (I2 below the full-crease level) is weighted in proportion
    quadric[0, 1, 0, 0, 0], quadric[0, 1, 0, 0, 1] = 0.95, 0.05  # I2 = 0.0475
    weight = 1 + 2.0 * 0.0475 / 0.1
    value, _ = AGNDCLoss(train_edges=False, quadric_floor=0.0, crease_weight=2.0)(
        pred, vertex, edge, surface, quadric=quadric)
    assert float(value) == pytest.approx((flat + weight * 0.95 * 0.25) / (1 + weight))
    with pytest.raises(ModelError, match="crease_weight"):
        AGNDCLoss(crease_weight=-1.0)


# ---------------------------------------------------------------------- band evaluation


def test_band_equals_dense_when_the_band_covers_the_lattice():
    """Every machinery piece (torus rows, windows, snakes, half lattices, sparse up-sampling)
    against the independent dense implementation: exact up to float rounding."""
    net = model()
    lattice = blob_lattice((24, 20, 16))
    with torch.inference_mode():
        dense = [p[0].permute(1, 2, 3, 0) for p in net(torch.from_numpy(lattice)[None])]
        band = net.forward_band(lattice, radius=40)
    for d, b in zip(dense, band):
        torch.testing.assert_close(b, d, atol=BAND_TOLERANCE, rtol=1e-5)


@pytest.mark.parametrize("kw, radius", [
    ({"levels": 2, "use_snake": False, "use_attention": False, "use_crpm": False}, 6),
    ({"levels": 1, "use_snake": False, "use_crpm": False}, 8),
])
def test_band_far_field_is_exact_within_the_receptive_field(kw, radius):
    """Networks whose receptive field the band covers: far points (most of the lattice) come
    from the torus rows, and the surface cells still match dense exactly."""
    net = model(**kw)
    lattice = blob_lattice()
    surface = surface_cells(crossed_edges(lattice))
    with torch.inference_mode():
        dense = net(torch.from_numpy(lattice)[None])[0][0].permute(1, 2, 3, 0)
        band = net.forward_band(lattice, radius=radius)[0]
    np.testing.assert_allclose(band[surface].numpy(), dense[surface].numpy(),
                               atol=BAND_TOLERANCE)


def test_band_evaluation_is_differentiable():
    net = model().train()
    lattice = blob_lattice((16, 16, 16))
    p0 = net.forward_band(lattice, radius=3)[0]
    p0.square().mean().backward()
    grads = [p.grad for p in net.nets[0].parameters()]
    assert all(g is not None for g in grads)
    assert sum(float(g.abs().sum()) for g in grads) > 0


# ---------------------------------------------------------------------- surface nets prior


@pytest.mark.parametrize("kw", [{}, {"levels": 0, "use_attention": False, "use_snake": False,
                                     "use_dffm": False, "use_crpm": False}])
def test_untrained_network_returns_surface_nets(kw):
    """Zero-initialised vertex heads + the prior: before any training the finest scale is
    exactly surface nets on every surface cell, dense and band alike."""
    from agndc_core.surfacenets import surface_nets_lattice

    torch.manual_seed(0)
    net = AGNDCCascade(AGNDCConfig(width=8, **kw)).eval()
    lattice = blob_lattice((24, 20, 16))
    surface = surface_cells(crossed_edges(lattice))
    expected = surface_nets_lattice(lattice)[surface]
    with torch.inference_mode():
        dense = net(torch.from_numpy(lattice)[None])[0][0].permute(1, 2, 3, 0)
        band = net.forward_band(lattice)[0]
    np.testing.assert_allclose(dense[..., :3][surface].numpy(), expected, atol=1e-6)
    np.testing.assert_allclose(band[..., :3][surface].numpy(), expected, atol=1e-6)
    # and the snakes start straight
    for module in net.modules():
        if hasattr(module, "offset") and hasattr(module, "taps"):
            assert int(torch.count_nonzero(module.offset.weight)) == 0


def test_crpm_sees_the_trunk_through_every_input_channel_at_initialisation():
    """Only the last layer before the vertex output starts at zero. CRPM reaches the trunk
    only through P'_s and W_s: had their vertex rows started at zero as well, two zero layers
    in series would hold each other's gradients at zero."""
    torch.manual_seed(0)
    net = AGNDCCascade(AGNDCConfig(width=8)).eval()
    lattice = blob_lattice((24, 20, 16))
    seen = {}
    for s, scale in enumerate(net.nets[:-1]):
        scale.crpm.register_forward_hook(
            lambda module, args, out, s=s: seen.__setitem__(s, (args[0], args[1])))
    with torch.inference_mode():
        net(torch.from_numpy(lattice)[None])
    surface = torch.from_numpy(surface_cells(crossed_edges(lattice)))
    for s, (w, p_iso) in seen.items():
        cells = surface if s == 0 else torch.ones(w.shape[1:4], dtype=torch.bool)
        for name, x in (("W", w), ("P'", p_iso)):
            spread = x[0][cells].std(dim=0)  # (6,) over the cells
            assert bool(torch.all(spread > 1e-3)), (s, name, spread)
    for scale in net.nets[:-1]:
        assert int(torch.count_nonzero(scale.crpm.head.fc2.weight[:3])) == 0


def test_without_the_prior_an_untrained_network_is_at_cell_centres():
    torch.manual_seed(0)
    net = AGNDCCascade(AGNDCConfig(width=8, surface_nets_prior=False)).eval()
    lattice = blob_lattice((16, 16, 16))
    with torch.inference_mode():
        p0 = net(torch.from_numpy(lattice)[None])[0][0]
    torch.testing.assert_close(p0[:3], torch.full_like(p0[:3], 0.5))


def test_edge_loss_can_be_left_out():
    pred = torch.randn(1, 6, 4, 4, 4, requires_grad=True)
    vertex, edge = torch.rand(1, 4, 4, 4, 3), torch.rand(1, 4, 4, 4, 3) > 0.5
    surface = torch.rand(1, 4, 4, 4) > 0.5
    loss, parts = AGNDCLoss(train_edges=False)(pred, vertex, edge, surface)
    loss.backward()
    assert parts["edge"] > 0 and float(pred.grad[:, 3:].abs().sum()) == 0.0
    assert float(pred.grad[:, :3].abs().sum()) > 0
