"""Guards against shipping weights that have not earned their place: the packaged checkpoints
must load without training code, describe themselves, and reconstruct held-out generated shapes
better than marching cubes on most shapes (and never much worse on any) and better than surface
nets (the no-learning method the networks correct) on average."""

import json

import numpy as np
import pytest

from agndc_core.checkpoint import count_parameters, default_checkpoint_path, load_checkpoint
from agndc_core.methods import CHECKPOINT_NAMES
from agndc_core.metrics import evaluate
from agndc_core.pipeline import remesh_mesh
from agndc_core.study.shapes import generate_shape
from agndc_core.study.solids import TARGETS, measure

#: seeds far outside the training (0..) and validation (1,000,000..) ranges
HELD_OUT_SEEDS = (7_000_001, 7_000_002, 7_000_003, 7_000_004, 7_000_005, 7_000_006)
RESOLUTION = 48
N_SAMPLES = 30_000
#: worst CD ratio to marching cubes allowed on any one held-out part
MAX_RATIO_TO_MC = 1.1
#: the packaged weights together must stay under a 25 MB budget (the extension's size)
WEIGHTS_BUDGET_BYTES = 25 * 1024 * 1024


def _shipped(name):
    """The shipped weights of a learned method."""
    path = default_checkpoint_path(CHECKPOINT_NAMES[name])
    if not path.is_file():
        pytest.fail(f"shipped weights missing: {path}")
    return path


@pytest.mark.parametrize("name", list(CHECKPOINT_NAMES))
def test_shipped_checkpoint_describes_itself(name):
    path = _shipped(name)
    sidecar = json.loads(path.with_suffix(".json").read_text())
    for key in ("model_config", "training", "metrics", "parameters", "weights_sha256"):
        assert key in sidecar, key
    assert sidecar["training"]["data"]["samples"] > 0
    model, meta = load_checkpoint(path)  # verifies the sha256 and the tensor shapes
    assert meta["model_config"] == sidecar["model_config"]
    assert count_parameters(model) == sidecar["parameters"]


def test_shipped_weights_fit_the_budget():
    folder = _shipped("agndc").parent
    total = sum(f.stat().st_size for f in folder.iterdir() if f.is_file())
    assert total <= WEIGHTS_BUDGET_BYTES


@pytest.mark.slow
@pytest.mark.parametrize("method", list(CHECKPOINT_NAMES))
def test_shipped_weights_beat_marching_cubes_and_surface_nets(method):
    _shipped(method)
    cd = {method: [], "mc": [], "surfacenets": []}
    for seed in HELD_OUT_SEEDS:
        vertices, faces = generate_shape(seed)
        for m in cd:
            # the grid alone: the mesh's bounding box would help surface nets as much; the
            # network's mesh as contoured: the normal filter would smooth surface nets too
            result = remesh_mesh(vertices, faces, resolution=RESOLUTION, method=m, threads=2,
                                 source_bounds=False, normal_filter=False)
            assert len(result.faces) > 0
            cd[m].append(evaluate(result.vertices, result.faces, vertices, faces,
                                  n_samples=N_SAMPLES)["cd"])
    # a broken checkpoint (e.g. offsets pushed out of their cells) is far worse than marching
    # cubes on every part; a good one may still lose a little on a mostly axis-aligned CAD part,
    # where the grid pins nothing down (an earlier shipped network: 4 % on seed 7000003)
    ratio = np.array(cd[method]) / np.array(cd["mc"])
    assert np.all(ratio < MAX_RATIO_TO_MC) and np.mean(ratio < 1.0) >= 2 / 3, cd
    # weights that learned nothing return surface nets (the prior): they must do better
    assert np.mean(cd[method]) < np.mean(cd["surfacenets"]), cd


@pytest.mark.slow
def test_shipped_agndc_meets_the_geometric_targets(tmp_path):
    """The analytic solids at 64³ (agndc_core/study/solids.py): flat box faces, the rotated box's
    faces and a sphere within their targets; the rotated box's corners (target 0.5 voxel, not
    met: 0.88 measured) at least nearer than surface nets puts them.

    The normal filter alone takes surface nets' faces and sphere within the targets too (0.058
    and 0.069 voxel), so the network must earn them twice: its own vertices, unfiltered, meet
    them where surface nets' do not, and filtered it beats weights that learned nothing (an
    untrained cascade: surface nets) filtered the same way."""
    import torch

    from agndc_core.checkpoint import save_checkpoint
    from agndc_core.nn import AGNDCCascade, AGNDCConfig

    _shipped("agndc")
    torch.manual_seed(0)
    nothing = save_checkpoint(AGNDCCascade(AGNDCConfig(width=8)), tmp_path / "untrained",
                              training={}, metrics={})
    agndc = measure("agndc", 64, threads=2)
    raw = measure("agndc", 64, threads=2, normal_filter=False)
    prior = measure("surfacenets", 64, threads=2)
    prior_filtered = measure("agndc", 64, threads=2, checkpoint=nothing)
    for name in ("flatness", "rotated_rms", "sphere"):
        assert agndc[name] <= TARGETS[name], (name, agndc)
    for name in ("rotated_rms", "sphere"):
        assert raw[name] <= TARGETS[name] < prior[name], (name, raw, prior)
    for name in ("corner", "sphere"):
        assert agndc[name] < prior_filtered[name], (name, agndc, prior_filtered)
    assert agndc["corner"] < prior["corner"], (agndc, prior)
