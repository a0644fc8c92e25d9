"""Training: exact crop augmentation, a short run that lowers the loss, and bit-exact resume."""

import json

import numpy as np
import pytest
import torch

from agndc_core.training.crops import make_crop, random_crop_origin, sample_pyramid, take
from agndc_core.training.data import build_dataset, flip_permute, load_sample
from agndc_core.training.train import TrainConfig, Trainer

TINY_MODEL = dict(width=8, window=2, heads=1, snake_kernel=3, band_radius=2)


@pytest.fixture(scope="module")
def data_dir(tmp_path_factory):
    folder = tmp_path_factory.mktemp("train_data")
    build_dataset(folder, 3, seed0=11, workers=1, progress=False)
    return folder


def _padded(sample: dict, n: int, levels: int) -> dict:
    """The sample zero-padded at the high end to an n^3 scale-0 lattice."""
    out = {}
    for s in range(levels + 1):
        m = n // 2 ** s
        for key in ("inside", "surface", "vertex", "edge"):
            arr = sample[f"{key}{s}"]
            out[f"{key}{s}"] = take(arr, (0, 0, 0), (m, m, m))
    out["lattice"] = take(sample["lattice"], (0, 0, 0), (n, n, n))
    return out


@pytest.mark.parametrize("seed", range(6))
def test_crop_augmentation_matches_whole_sample_flip(data_dir, seed):
    levels = 2
    sample = load_sample(sorted(data_dir.glob("*.npz"))[0])
    n = -(-max(sample["lattice"].shape) // 4) * 4
    padded = _padded(sample, n, levels)
    rng = np.random.default_rng(seed)
    perm, flips = rng.permutation(3), rng.random(3) < 0.5
    # flip_permute draws the same permutation and flips from an identically seeded generator
    expected = flip_permute(padded, levels, np.random.default_rng(seed))
    grids = sample_pyramid(padded["lattice"], levels)
    for s in range(levels + 1):
        crop = make_crop(padded, grids, s, n // 2 ** s, (0, 0, 0), perm, flips)
        np.testing.assert_array_equal(crop["surface"], expected[f"surface{s}"])
        np.testing.assert_array_equal(crop["edge"], expected[f"edge{s}"])
        np.testing.assert_allclose(crop["vertex"], expected[f"vertex{s}"], atol=1e-6)
        np.testing.assert_array_equal(crop["g"][0], sample_pyramid(expected["lattice"], s)[s])


def test_crop_origin_is_aligned_and_contains_surface(data_dir):
    sample = load_sample(sorted(data_dir.glob("*.npz"))[1])
    rng = np.random.default_rng(0)
    for _ in range(20):
        origin = random_crop_origin(sample["surface0"], 16, 8, rng)
        assert all(o % 8 == 0 for o in origin)
        assert take(sample["surface0"], origin, (16, 16, 16)).any()


def _config(data_dir, out, steps=(4, 3, 3)):
    return TrainConfig(data=str(data_dir), out=str(out), model=TINY_MODEL, steps=list(steps),
                       batch=2, crop=16, lr=3e-3, warmup=2, log_every=1, save_every=2)


def test_short_run_lowers_loss_and_writes_checkpoint(data_dir, tmp_path):
    from agndc_core.checkpoint import load_checkpoint

    cfg = _config(data_dir, tmp_path / "run", steps=(25, 2, 2))
    trainer = Trainer(cfg)
    path = trainer.run(progress=False)
    scale0 = [e["vertex"] for e in trainer.log if e["scale"] == 0]
    assert np.mean(scale0[-5:]) < 0.5 * np.mean(scale0[:3])
    model, meta = load_checkpoint(path)
    assert meta["training"]["steps_per_scale"] == [25, 2, 2]
    assert meta["training"]["data"]["samples"] == 3
    info = json.loads((tmp_path / "run" / "run.json").read_text())
    assert info["done"]


def test_resume_is_bit_exact(data_dir, tmp_path):
    whole = Trainer(_config(data_dir, tmp_path / "whole"))
    whole.run(progress=False)
    # stop after scale 2 and 1 of scale 1's steps, resume in a new trainer
    first = Trainer(_config(data_dir, tmp_path / "split"))
    first.cfg.steps = [4, 1, 3]
    for s in (2, 1):
        first.scale, first.step = s, 0
        first.optimizer = first._optimizer(s)
        while first.step < first.cfg.steps[s]:
            first.train_step(s, first.step)
            first.step += 1
    first.save_state()
    second = Trainer(_config(data_dir, tmp_path / "split"))
    assert second.resume()
    second.run(progress=False)
    for (name, a), (_, b) in zip(whole.model.state_dict().items(),
                                 second.model.state_dict().items()):
        assert torch.equal(a, b), name
