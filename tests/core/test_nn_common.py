"""The geometry helpers both evaluation paths share (``nn/common.py``), against slow references.

Band == dense cannot catch a bug here, because both paths call these helpers; so each is
checked against a loop written from its definition.
"""

import itertools
import math

import numpy as np
import pytest
import torch

from agndc_core.grid import scale_lattice
from agndc_core.nn.common import (
    CELL_CORNERS,
    cell_surface,
    child_prediction,
    snake_corners,
    snake_offsets,
)


def test_snake_offsets_are_cumulative_bounded_drifts():
    torch.manual_seed(0)
    delta = torch.randn(5, 2, 7) * 3
    scope = 1.5
    got = snake_offsets(delta, scope)
    step = np.tanh(delta.numpy()) * scope
    c = 3
    for t in range(7):
        taps = range(c + 1, t + 1) if t > c else range(t, c)  # centre excluded
        want = step[..., list(taps)].sum(-1)
        np.testing.assert_allclose(got[..., t].numpy(), want, atol=1e-5)
    # neighbouring taps never drift more than the scope
    assert float((got[..., 1:] - got[..., :-1]).abs().max()) <= scope + 1e-6


def test_snake_corners_interpolate_bilinearly_across_the_lateral_axes():
    rng = np.random.default_rng(1)
    field = rng.normal(size=(12, 12, 12))
    coords = torch.tensor([[5, 6, 4], [3, 7, 8]])
    offsets = torch.tensor(rng.uniform(-2.5, 2.5, size=(2, 2, 5)), dtype=torch.float32)
    for axis in range(3):
        corners, weights = snake_corners(coords, offsets, axis)
        got = (weights.numpy() * field[tuple(corners.numpy().reshape(-1, 3).T)].reshape(
            weights.shape)).sum(-1)
        lateral = [a for a in range(3) if a != axis]
        for n, t in itertools.product(range(2), range(5)):
            pos = coords[n].numpy().astype(float)
            pos[axis] += t - 2
            pos[lateral[0]] += float(offsets[n, 0, t])
            pos[lateral[1]] += float(offsets[n, 1, t])
            want = _bilinear(field, pos, lateral)
            assert math.isclose(got[n, t], want, rel_tol=1e-4, abs_tol=1e-5)
        np.testing.assert_allclose(weights.sum(-1).numpy(), 1.0, atol=1e-6)


def _bilinear(field, pos, lateral):
    """Value of ``field`` at ``pos`` (integer along the non-lateral axis), by the definition."""
    b, c = lateral
    fb, fc = math.floor(pos[b]), math.floor(pos[c])
    total = 0.0
    for db, dc in itertools.product((0, 1), repeat=2):
        point = [int(round(x)) for x in pos]
        point[b], point[c] = fb + db, fc + dc
        weight = (1 - abs(pos[b] - point[b])) * (1 - abs(pos[c] - point[c]))
        total += weight * field[tuple(point)]
    return total


def test_dense_snake_matches_the_definition_with_replicated_borders():
    """DenseOps.snake (grid_sample) against the tap sum written from the definition; the
    offsets reach past the lattice, where the border point is replicated."""
    from agndc_core.nn.dense_ops import DenseOps

    rng = np.random.default_rng(2)
    shape, k, b = (6, 5, 7), 5, 2
    y = rng.normal(size=(1, *shape, k * b))
    offsets = rng.uniform(-3.0, 3.0, size=(1, *shape, 2, k))
    ops = DenseOps(shape)
    for axis in range(3):
        got = ops.snake(torch.tensor(y, dtype=torch.float32),
                        torch.tensor(offsets, dtype=torch.float32), axis).numpy()
        lateral = [a for a in range(3) if a != axis]
        for point in itertools.product(*map(range, shape)):
            want = np.zeros(b)
            for t in range(k):
                pos = np.array(point, dtype=float)
                pos[axis] += t - k // 2
                pos[lateral] += offsets[(0, *point, slice(None), t)]
                pos = np.clip(pos, 0, np.array(shape) - 1)  # replicate border
                for c in range(b):
                    # one replicated layer so a weight-0 corner past the border can be read
                    field = np.pad(y[0, ..., t * b + c], 1, mode="edge")
                    want[c] += _bilinear(field, pos + 1, lateral)
            np.testing.assert_allclose(got[(0, *point)], want, rtol=1e-4, atol=1e-4)


def test_cell_surface_reads_the_cells_twelve_edges():
    """A cell is a surface cell if one of its 12 edges (grid.py convention: x-edges leave
    corners (0, dy, dz), ...) is likely crossed; probabilities elsewhere do not count."""
    rng = np.random.default_rng(2)
    corners = CELL_CORNERS.numpy()
    for _ in range(200):
        q = rng.uniform(0, 0.5, size=(8, 3))
        hot = rng.integers(8), rng.integers(3)
        q[hot] = 0.9 if rng.random() < 0.7 else 0.3
        want = any(q[i, axis] > 0.5 for i, corner in enumerate(corners) for axis in range(3)
                   if corner[axis] == 0)  # the edge from this corner along +axis is the cell's
        assert bool(cell_surface(torch.tensor(q))) == want


def test_child_prediction_keeps_the_coarse_vertex_in_place():
    """A coarse vertex keeps its fine-lattice position when re-expressed in each child cell."""
    rng = np.random.default_rng(3)
    offset, spacing = scale_lattice(1)
    for _ in range(20):
        coarse_cell = rng.integers(0, 10, size=3)
        p = torch.tensor(np.concatenate([rng.uniform(0, 1, 3), rng.normal(size=3)]))
        fine_position = spacing * (coarse_cell + p[:3].numpy()) + offset
        for child in itertools.product((0, 1), repeat=3):
            out = child_prediction(p, torch.tensor(True), torch.tensor(child))
            child_cell = 2 * coarse_cell + np.array(child)
            np.testing.assert_allclose(child_cell + out[:3].numpy(), fine_position, atol=1e-9)
            np.testing.assert_allclose(out[3:].numpy(), torch.sigmoid(p[3:]).numpy())
        assert torch.all(child_prediction(p, torch.tensor(False), torch.tensor(child)) == 0)


@pytest.mark.parametrize("lows, highs", [((1, 1, 1), (1, 1, 1)), ((0, 2, 1), (3, 0, 1)),
                                         ((0, 0, 0), (1, 1, 1))])
def test_replicate_padding_under_torch_compile_is_f_pad(lows, highs):
    """Traced, ``replicate_pad`` concatenates border planes; the values are F.pad's."""
    import torch.nn.functional as F

    from agndc_core.nn.dense_ops import replicate_pad

    x = torch.randn(2, 3, 4, 5, 6)
    pads = [p for lo, hi in reversed(list(zip(lows, highs))) for p in (lo, hi)]
    expected = F.pad(x, pads, mode="replicate")
    assert torch.equal(replicate_pad(x, lows, highs), expected)
    traced = torch.compile(lambda t: replicate_pad(t, lows, highs), backend="aot_eager",
                           fullgraph=True)
    assert torch.equal(traced(x), expected)


def test_inductor_compiles_a_convolution_of_the_upsampled_prediction():
    """The pattern inductor failed on (a replicate-padded convolution of the sparse
    up-sampling), compiled to generated code, against eager."""
    from agndc_core.nn.dense_ops import DenseOps

    torch.manual_seed(0)
    ops, conv = DenseOps((8, 8, 8)), torch.nn.Conv3d(6, 4, 3)
    p = torch.randn(2, 4, 4, 4, 6)

    def conv_of_upsampled(p):
        return ops.conv(ops.upsample_prediction(p), conv)

    with torch.no_grad():
        compiled = torch.compile(conv_of_upsampled, backend="inductor", fullgraph=True)
        torch.testing.assert_close(compiled(p), conv_of_upsampled(p))
