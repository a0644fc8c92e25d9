"""Training: exact crop augmentation, a short run that lowers the loss, and bit-exact resume."""

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from agndc_core.errors import AGNDCError
from agndc_core.grid import occupancy_pyramid as sample_pyramid
from agndc_core.training import train as train_module
from agndc_core.training.crops import SparseSample, make_crop, random_crop_origin, take, valid_cells
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


def test_outside_crops_reach_past_the_lattice_and_still_hold_surface(data_dir):
    """``outside=True``: aligned origins, each crop holds surface, and crops do reach past
    both ends of the lattice (where the default never does)."""
    sample = load_sample(sorted(data_dir.glob("*.npz"))[1])
    cells, dims = np.argwhere(sample["surface0"]), sample["surface0"].shape
    past_low = past_high = 0
    for outside in (False, True):
        rng = np.random.default_rng(5)
        for _ in range(200):
            origin = random_crop_origin(cells, 16, 8, rng, 2, dims=dims, outside=outside)
            assert all(o % 8 == 0 for o in origin)
            assert take(sample["surface0"], origin, (16, 16, 16)).any()
            low = any(o < 0 for o in origin)
            high = any(o + 16 > d for o, d in zip(origin, dims))
            if not outside:
                assert not low and not high
            past_low, past_high = past_low + low, past_high + high
    assert past_low > 0 and past_high > 0


@pytest.mark.parametrize("outside", [False, True])
def test_sparse_sample_windows_give_the_dense_crops(data_dir, outside):
    """The trainer's path (sparse sample -> dense window -> crop) equals cropping the dense
    sample directly, for every scale, flip and permutation (crops past the lattice too)."""
    levels = 2
    sample = load_sample(sorted(data_dir.glob("*.npz"))[2])
    sparse = SparseSample(sample, levels)
    grids = sample_pyramid(sample["lattice"], levels)
    rng = np.random.default_rng(3)
    for s in range(levels + 1):
        align, size = 4 * 2 ** (levels - s), 16 // 2 ** s if s < 2 else 8
        for _ in range(4):
            origin = random_crop_origin(sparse.cells[s], size, align, rng, 2,
                                        dims=sparse.shapes[s], outside=outside)
            perm, flips = rng.permutation(3), rng.random(3) < 0.5
            want = make_crop(sample, grids, s, size, origin, perm, flips)
            window = sparse.window(s, np.asarray(origin) - align, [size + 2 * align] * 3)
            got = make_crop(window, [None] * s + window.pop("grids"), s, size, [align] * 3,
                            perm, flips)
            for key in ("surface", "edge", "vertex", "quadric"):
                np.testing.assert_array_equal(got[key], want[key])
            for a, b in zip(got["g"], want["g"]):
                np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("s", [0, 1])
def test_a_crop_at_any_phase_is_the_aligned_crop_of_the_moved_part(data_dir, s):
    """``random_phase``: a crop starting between window boundaries is exactly the aligned crop
    of the sample whose part was moved by that phase (every label, every pooled input)."""
    levels = 2
    sample = load_sample(sorted(data_dir.glob("*.npz"))[0])
    sparse = SparseSample(sample, levels)
    align = size = 4 * 2 ** (levels - s)
    rng = np.random.default_rng(s)
    for _ in range(4):
        phase = rng.integers(1, align, size=3)
        fine = phase * 2 ** s
        extent = -(-np.add(sample["lattice"].shape, fine) // 2 ** levels) * 2 ** levels
        moved = {"lattice": take(sample["lattice"], -fine, extent)}
        for key in ("surface", "vertex", "edge", "quadric"):
            arr = sample[f"{key}{s}"]
            moved[f"{key}{s}"] = take(arr, -phase, np.add(arr.shape[:3], phase))
        aligned = np.asarray(random_crop_origin(moved[f"surface{s}"], size, align, rng))
        perm, flips = rng.permutation(3), rng.random(3) < 0.5
        want = make_crop(moved, sample_pyramid(moved["lattice"], levels), s, size, aligned,
                         perm, flips)
        origin = aligned - phase  # the same cells in the sample's own lattice
        window = sparse.window(s, origin - align, [size + 2 * align] * 3)
        got = make_crop(window, [None] * s + window.pop("grids"), s, size, [align] * 3,
                        perm, flips)
        assert got["surface"].any()
        for key in ("surface", "edge", "vertex", "quadric"):
            np.testing.assert_array_equal(got[key], want[key])
        for a, b in zip(got["g"], want["g"]):
            np.testing.assert_array_equal(a, b)


def test_random_phase_batches_start_between_window_boundaries(data_dir, monkeypatch):
    """The trainer draws unaligned origins only with ``random_phase``."""
    origins = []

    def spy(*args, **kwargs):
        origin = random_crop_origin(*args, **kwargs)
        origins.append(origin)
        return origin

    monkeypatch.setattr(train_module, "random_crop_origin", spy)
    from agndc_core.nn import AGNDCConfig

    model_config = AGNDCConfig(**TINY_MODEL)
    samples = train_module._load_folder(str(data_dir), model_config.levels, 0)
    align = model_config.window * 2 ** model_config.levels  # scale 0's window boundaries
    for random_phase in (False, True):
        cfg = TrainConfig(data=str(data_dir), out="unused", batch=4, crop=[16, 8, 4],
                          random_phase=random_phase)
        origins.clear()
        for step in range(4):
            batch = train_module.make_batch(cfg, model_config, samples, 0, step)
            assert batch["surface"].any()
        unaligned = [o for o in origins if any(x % align for x in o)]
        assert bool(unaligned) == random_phase


@pytest.mark.parametrize("seed", range(8))
def test_valid_cells_follow_the_crop_through_flips(seed):
    """``valid_cells`` against the mask built in the lattice frame and pushed through
    ``make_crop`` like any cell label."""
    rng = np.random.default_rng(seed)
    size, margin = 10, 2
    dims = tuple(int(x) for x in rng.integers(12, 20, size=3))
    origin = [int(rng.choice([0, 2, d - size, d - size + 3])) for d in dims]
    perm, flips = rng.permutation(3), rng.random(3) < 0.5
    cell = [np.arange(d) - o for d, o in zip(dims, origin)]
    ok = [((c >= margin) | (o <= 0)) & ((c <= size - 2 - margin) | (o + size >= d))
          for c, o, d in zip(cell, origin, dims)]
    mask = ok[0][:, None, None] & ok[1][None, :, None] & ok[2][None, None, :]
    zeros = np.zeros(dims + (3,))

    def through_crop(cells):
        sample = {"surface0": cells, "vertex0": zeros, "edge0": zeros > 0}
        return make_crop(sample, [np.zeros(dims, bool)], 0, size, origin, perm, flips)["surface"]

    # cells beyond the lattice have no labels at all (zero-filled), so they are not compared
    in_lattice = through_crop(np.ones(dims, bool))
    valid = valid_cells(origin, size, dims, margin, perm, flips)
    np.testing.assert_array_equal(valid[in_lattice], through_crop(mask)[in_lattice])
    assert 0 < valid.sum() < size**3


def test_binary_targets_replace_only_the_depth_the_grid_cannot_show(data_dir):
    """``binary_targets``: on exactly axis-aligned surface cells of scale 0 the target's
    coordinate along the normal becomes the surface nets midpoint; nothing else changes (the
    other coordinates, other cells, the inputs, the coarser scales)."""
    from agndc_core.nn import AGNDCConfig
    from agndc_core.surfacenets import surface_nets_lattice
    from agndc_core.tolerances import tol

    model_config = AGNDCConfig(**TINY_MODEL)
    samples = train_module._load_folder(str(data_dir), model_config.levels, 0)
    plain = TrainConfig(data=str(data_dir), out="unused", batch=4, crop=[16, 8, 4])
    binary = TrainConfig(**{**plain.__dict__, "binary_targets": True})
    changed = 0
    for step in range(6):
        a = train_module.make_batch(plain, model_config, samples, 0, step)
        b = train_module.make_batch(binary, model_config, samples, 0, step)
        for key in ("surface", "valid", "quadric", "edge"):
            assert torch.equal(a[key], b[key])
        assert all(torch.equal(x, y) for x, y in zip(a["g"], b["g"]))
        aligned = (a["quadric"][..., :3] > tol.axis_aligned) & a["surface"][..., None]
        midpoints = torch.stack([torch.from_numpy(surface_nets_lattice(g.numpy()))
                                 for g in a["g"][0]])
        assert torch.equal(b["vertex"][aligned], midpoints[aligned])
        assert torch.equal(b["vertex"][~aligned], a["vertex"][~aligned])
        # a flat voxel face splits its cells purely: the midpoint is the layer's middle (bar a
        # cell a perpendicular face barely enters, below the quadric's tolerance)
        middle = b["vertex"][aligned] == 0.5
        assert middle.float().mean() > 0.99 if middle.numel() else True
        changed += int((b["vertex"] != a["vertex"]).sum())
    assert changed > 100  # the fixture has an axis-aligned part whose faces lie off-centre
    coarse = [train_module.make_batch(c, model_config, samples, 1, 0) for c in (plain, binary)]
    assert torch.equal(coarse[0]["vertex"], coarse[1]["vertex"])


def _config(data_dir, out, steps=(4, 3, 3)):
    return TrainConfig(data=str(data_dir), out=str(out), model=TINY_MODEL, steps=list(steps),
                       batch=2, crop=16, margin=[2, 2, 0], lr=3e-3, warmup=2, log_every=1,
                       save_every=2)


def _held_out_loss(trainer, steps=range(10_000, 10_006)) -> float:
    """Mean finest-scale vertex loss of the model on fixed batches no step trains on."""
    with torch.no_grad():
        losses = []
        for step in steps:
            batch = trainer.batch(0, step)
            pred = trainer.model.forward_scale(0, batch["g"][0],
                                               trainer.predict_coarser(0, batch["g"]))
            _, parts = trainer.losses[0](pred, batch["vertex"], batch["edge"],
                                         batch["surface"] & batch["valid"], batch["valid"],
                                         batch.get("quadric"))
            losses.append(parts["vertex"])
    return float(np.mean(losses))


def test_quadric_floor_reaches_every_scale_loss(data_dir, tmp_path):
    """The recipe's quadric floor is the one every scale's loss uses (default: nn.loss's)."""
    cfg = _config(data_dir, tmp_path / "run")
    cfg.quadric_floor = 0.7
    trainer = Trainer(cfg)
    assert [loss.quadric_floor for loss in trainer.losses] == [0.7] * 3
    assert Trainer(_config(data_dir, tmp_path / "default")).losses[0].quadric_floor == 0.1


def test_crease_weight_reaches_every_scale_loss_and_the_lineage(data_dir, tmp_path):
    """--crease-weight is what every scale's loss weights creases by (default 0: off), and a
    lineage entry records it with the other loss options."""
    from agndc_core.training.train import LINEAGE_OPTIONS
    cfg = _config(data_dir, tmp_path / "run")
    cfg.crease_weight = 3.0
    assert [loss.crease_weight for loss in Trainer(cfg).losses] == [3.0] * 3
    assert Trainer(_config(data_dir, tmp_path / "default")).losses[0].crease_weight == 0.0
    assert "crease_weight" in LINEAGE_OPTIONS


@pytest.mark.slow
def test_short_run_improves_on_surface_nets_and_writes_checkpoint(data_dir, tmp_path):
    """An untrained network *is* surface nets (zero vertex heads + prior); a short run must do
    clearly better than that on batches it never saw. The single-scale plain-conv network
    (UNDC) learns fastest per second, so it keeps this test short. (400 steps: on the labels
    with exact edge crossings 200 steps reached 0.88 of the surface nets loss, where the
    sample-only labels reached 0.75; 400 reach 0.68.)"""
    from agndc_core.checkpoint import load_checkpoint

    cfg = _config(data_dir, tmp_path / "run", steps=(400,))
    cfg.model = dict(width=8, levels=0, use_attention=False, use_snake=False, use_dffm=False,
                     use_crpm=False)
    trainer = Trainer(cfg)
    before = _held_out_loss(trainer)
    path = trainer.run(progress=False)
    assert _held_out_loss(trainer) < 0.85 * before
    model, meta = load_checkpoint(path)
    assert meta["training"]["steps_per_scale"] == [400]
    assert meta["training"]["data"]["samples"] == 3
    assert meta["training"]["hardware"].startswith("CPU, ")  # what the step times were on
    # the wait for batches is part of the step time, never more
    assert 0 < meta["training"]["data_wait_seconds"] < meta["training"]["train_seconds"]
    info = json.loads((tmp_path / "run" / "run.json").read_text())
    assert info["done"]


@pytest.mark.slow
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


def test_a_run_resumed_elsewhere_records_both_machines(data_dir, tmp_path):
    """Steps run on one machine and finished on another (the CPU, then a GPU): the
    checkpoint says where each part ran, not only the last machine's name."""
    from agndc_core.checkpoint import load_checkpoint

    cfg = _config(data_dir, tmp_path / "run")
    cfg.threads, cfg.max_seconds = 2, 1e-9  # stops after its first step, the state saved
    assert Trainer(cfg).run(progress=False) is None
    cfg = _config(data_dir, tmp_path / "run")
    cfg.threads = 1  # another machine, as far as the record can tell
    second = Trainer(cfg)
    assert second.resume()
    _, meta = load_checkpoint(second.run(progress=False))
    sessions = meta["training"]["sessions"]
    assert [e["hardware"].split(",")[1].strip() for e in sessions] == ["2 threads", "1 threads"]
    assert sessions[0]["from"] == {"scale": 2, "step": 0}
    assert sessions[1]["from"] == {"scale": 2, "step": 1}
    assert "from scale 2 step 1" in meta["training"]["hardware"]


@pytest.mark.slow
def test_a_warm_started_checkpoint_carries_its_lineage(data_dir, tmp_path):
    """Weights continued through --init say which runs they descend from, oldest first, and
    how long all of them trained: shipped weights describe themselves without hand edits."""
    from agndc_core.checkpoint import load_checkpoint

    paths, records = [], []
    for name, lr in (("first", 3e-3), ("second", 1e-3), ("third", 5e-4)):
        cfg = _config(data_dir, tmp_path / name, steps=(2, 1, 1))
        cfg.lr, cfg.init = lr, (str(paths[-1]) if paths else None)
        paths.append(Trainer(cfg).run(progress=False))
        records.append(load_checkpoint(paths[-1])[1]["training"])
    lineage = records[-1]["lineage"]
    assert [Path(e["run"]).name for e in lineage] == ["first", "second", "third"]
    assert [e["lr"] for e in lineage] == [3e-3, 1e-3, 5e-4]
    assert lineage[1]["init"] == str(paths[0]) and lineage[0]["init"] is None
    assert lineage[:2] == records[1]["lineage"]  # each run extends its parent's lineage
    assert records[-1]["total_train_seconds"] == pytest.approx(
        sum(r["train_seconds"] for r in records), abs=0.2)
    assert all(e["hardware"].startswith("CPU, ") for e in lineage)


def test_state_is_sharded_under_the_file_limit_and_resumes(data_dir, tmp_path, monkeypatch):
    monkeypatch.setattr(train_module, "MAX_FILE_BYTES", 40_000)
    trainer = Trainer(_config(data_dir, tmp_path / "run"))
    trainer.train_step(2, 0)
    trainer.save_state()
    shards = sorted((tmp_path / "run").glob("state-*.safetensors"))
    assert len(shards) > 1
    biggest = max(p.numel() * p.element_size() for p in trainer.model.parameters())
    assert all(p.stat().st_size <= 40_000 + biggest + 4096 for p in shards)
    again = Trainer(_config(data_dir, tmp_path / "run"))
    assert again.resume()
    for (name, a), (_, b) in zip(trainer.model.state_dict().items(),
                                 again.model.state_dict().items()):
        assert torch.equal(a, b), name


def test_warm_start_from_a_checkpoint_without_the_prior(data_dir, tmp_path):
    """A checkpoint that predicted absolute offsets starts a prior run: its weights are kept,
    only the finest scale's last vertex layer restarts (at surface nets)."""
    from agndc_core.checkpoint import save_checkpoint
    from agndc_core.nn import AGNDCCascade, AGNDCConfig

    torch.manual_seed(5)
    old = AGNDCCascade(AGNDCConfig(**TINY_MODEL, surface_nets_prior=False))
    for p in old.parameters():
        p.data.normal_()
    path = save_checkpoint(old, tmp_path / "old", training={}, metrics={})
    cfg = _config(data_dir, tmp_path / "run")
    cfg.init = str(path)
    new = Trainer(cfg).model
    head = new.nets[0].crpm.head.fc2
    assert int(torch.count_nonzero(head.weight[:3])) == 0 and torch.all(head.bias[:3] == 0.5)
    torch.testing.assert_close(head.weight[3:], old.nets[0].crpm.head.fc2.weight[3:])
    # CRPM's inputs keep what they learned: only the last layer restarts
    torch.testing.assert_close(new.nets[0].fdm.head.fc2.weight, old.nets[0].fdm.head.fc2.weight)
    torch.testing.assert_close(new.nets[0].dffm.out.weight, old.nets[0].dffm.out.weight)
    torch.testing.assert_close(new.nets[1].fdm.convs[0].weight, old.nets[1].fdm.convs[0].weight)


def test_an_ablation_warm_starts_from_the_full_model_only_when_asked(data_dir, tmp_path):
    """--init-matching: a Table 4 variant takes every tensor it shares with the full model by
    name and shape and starts the rest fresh; without the flag, or when more than the ablation
    switches differ, the checkpoint is refused naming the fields."""
    from agndc_core.checkpoint import save_checkpoint
    from agndc_core.errors import AGNDCError
    from agndc_core.nn import AGNDCCascade, AGNDCConfig

    torch.manual_seed(6)
    full = AGNDCCascade(AGNDCConfig(**TINY_MODEL))
    for p in full.parameters():
        p.data.normal_()
    path = save_checkpoint(full, tmp_path / "full", training={}, metrics={})
    theirs = full.state_dict()

    def start(name, steps=(4, 3, 3), matching=True, **switches):
        cfg = _config(data_dir, tmp_path / name, steps)
        cfg.model = {**TINY_MODEL, **switches}
        cfg.init, cfg.init_matching = str(path), matching
        return Trainer(cfg)

    with pytest.raises(AGNDCError, match=r"levels.*--init-matching"):
        start("refused", steps=(4,), matching=False, levels=0)
    with pytest.raises(AGNDCError, match="width") as refused:
        start("wider", width=12)
    assert "--init-matching" not in str(refused.value)

    # +GDFEM (one scale): the finest scale's GDFEM and FDM, nothing fresh
    one_scale = start("one_scale", steps=(4,), levels=0)
    assert one_scale.warm_start["fresh"] == []
    assert one_scale.warm_start["dropped"] == ["nets.0.crpm", "nets.0.dffm", "nets.1.crpm",
                                               "nets.1.dffm", "nets.1.fdm", "nets.1.gdfem",
                                               "nets.2.fdm", "nets.2.gdfem"]
    for name, value in one_scale.model.state_dict().items():
        torch.testing.assert_close(value, theirs[name])
    # without attention the snakes' input loses the attention channel: they start fresh
    no_lwsa = start("no_lwsa", use_attention=False)
    assert no_lwsa.warm_start["fresh"] == [f"nets.{s}.gdfem" for s in range(3)]
    mine = no_lwsa.model.state_dict()
    torch.testing.assert_close(mine["nets.0.gdfem.convs.2.weight"],
                               theirs["nets.0.gdfem.convs.2.weight"])
    assert mine["nets.0.gdfem.dynamic.0.fuse.weight"].shape != \
        theirs["nets.0.gdfem.dynamic.0.fuse.weight"].shape
    record = no_lwsa.training_record()["warm_start"]
    assert record["checkpoint"] == str(path) and record["loaded"] < len(theirs)


@pytest.mark.parametrize("seed", range(6))
def test_quadric_transform_keeps_the_error_measure(seed):
    """A flip negates a displacement's component, a permutation reorders it; the quadric must
    follow so that d^T Q d is unchanged."""
    from agndc_core.labels import QUADRIC_ENTRIES
    from agndc_core.training.crops import transform_quadric

    rng = np.random.default_rng(seed)
    a = rng.normal(size=(5, 3, 3))
    full = a @ a.transpose(0, 2, 1)
    q6 = np.stack([full[:, r, c] for r, c in QUADRIC_ENTRIES], 1).astype(np.float32)
    d = rng.normal(size=(5, 3))
    perm, flips = rng.permutation(3), rng.random(3) < 0.5
    moved = np.where(flips, -d, d)[:, perm]
    q_new = transform_quadric(q6, perm, flips)
    new = np.zeros((5, 3, 3))
    for k, (r, c) in enumerate(QUADRIC_ENTRIES):
        new[:, r, c] = new[:, c, r] = q_new[:, k]
    np.testing.assert_allclose(np.einsum("ni,nij,nj->n", moved, new, moved),
                               np.einsum("ni,nij,nj->n", d, full, d), rtol=1e-5)


def test_samples_read_by_worker_processes_are_the_same(data_dir):
    """Reading the folder with worker processes keeps the path order and every array."""
    from agndc_core.training.train import _load_folder

    serial, parallel = _load_folder(data_dir, 2), _load_folder(data_dir, 2, workers=2)
    assert [x.recipe for x in serial] == [x.recipe for x in parallel]
    for a, b in zip(serial, parallel):
        np.testing.assert_array_equal(a.bits, b.bits)
        for s in range(3):
            np.testing.assert_array_equal(a.cells[s], b.cells[s])
            np.testing.assert_array_equal(a.vertex[s], b.vertex[s])
            np.testing.assert_array_equal(a.quadric[s], b.quadric[s])


def test_worker_processes_build_the_same_batches(data_dir, tmp_path):
    """--workers only moves crop building into other processes: step k's batch is the same."""
    trainer = Trainer(_config(data_dir, tmp_path / "run"))
    trainer.cfg.workers = 2
    parallel = list(trainer._batches(0, 2, 5))
    trainer.cfg.workers = 0
    serial = list(trainer._batches(0, 2, 5))
    for a, b in zip(parallel, serial):
        assert a.keys() == b.keys()
        for key in a:
            pairs = zip(a[key], b[key]) if key == "g" else [(a[key], b[key])]
            assert all(torch.equal(x, y) for x, y in pairs), key


def test_weight_average_follows_the_steps_and_leaves_the_raw_weights(data_dir, tmp_path):
    """With decay d the average after steps 1, 2 is d²·w0 + d(1-d)·w1 + (1-d)·w2; scoring
    swaps it in and puts the trained weights back."""
    cfg = _config(data_dir, tmp_path / "run")
    cfg.ema = 0.75
    trainer = Trainer(cfg)
    trainer.scale, trainer.optimizer = 0, trainer._optimizer(0)
    trainer.ema = trainer._start_ema(0)
    net = trainer.model.nets[0]
    weights = [{k: p.detach().clone() for k, p in net.named_parameters()}]
    for step in range(2):
        trainer.train_step(0, step)
        weights.append({k: p.detach().clone() for k, p in net.named_parameters()})
    w0, w1, w2 = weights
    moved = [k for k in w0 if not torch.equal(w0[k], w2[k])]
    assert moved  # the steps changed something, so the test can tell the average apart
    for k in w0:
        expected = 0.75**2 * w0[k] + 0.75 * 0.25 * w1[k] + 0.25 * w2[k]
        torch.testing.assert_close(trainer.ema[k], expected)
    with trainer.averaged() as model:
        torch.testing.assert_close(dict(model.nets[0].named_parameters())[moved[0]],
                                   trainer.ema[moved[0]])
    for k, p in net.named_parameters():
        assert torch.equal(p, w2[k]), k


@pytest.mark.slow
def test_checkpoint_keeps_the_average_and_resume_is_bit_exact(data_dir, tmp_path):
    """A run with a weight average, stopped after every step and resumed, ends with the same
    checkpoint as one uninterrupted run; the checkpoint differs from an unaveraged run."""
    from agndc_core.checkpoint import load_checkpoint

    def final(out, ema, max_seconds=None):
        while True:
            cfg = _config(data_dir, out)
            cfg.ema, cfg.max_seconds = ema, max_seconds
            trainer = Trainer(cfg)
            trainer.resume()
            path = trainer.run(progress=False)
            if path is not None:
                return load_checkpoint(path)[0].state_dict()

    whole = final(tmp_path / "whole", 0.5)
    split = final(tmp_path / "split", 0.5, max_seconds=1e-9)
    plain = final(tmp_path / "plain", 0.0)
    for name in whole:
        assert torch.equal(whole[name], split[name]), name
    assert any(not torch.equal(whole[n], plain[n]) for n in whole if n.startswith("nets.0."))


def test_learning_curve_steps_write_checkpoints_of_the_averaged_weights(data_dir, tmp_path):
    """--val-steps 1,4 of a 4-step finest scale: two loadable checkpoints; the last one is the
    final checkpoint (both keep the weight average), the first one has only the finest
    scale's network behind it."""
    from agndc_core.checkpoint import load_checkpoint

    cfg = _config(data_dir, tmp_path / "run")
    cfg.ema, cfg.val_steps = 0.5, [1, 4]
    final = Trainer(cfg).run(progress=False)
    assert sorted(p.name for p in (tmp_path / "run").glob("step-*.safetensors")) == \
        ["step-000001.safetensors", "step-000004.safetensors"]
    first, meta = load_checkpoint(tmp_path / "run" / "step-000001.safetensors")
    last = load_checkpoint(tmp_path / "run" / "step-000004.safetensors")[0].state_dict()
    final = load_checkpoint(final)[0].state_dict()
    assert meta["training"]["steps_done"] == {"scale": 0, "step": 1}
    for name, value in first.state_dict().items():
        assert torch.equal(last[name], final[name]), name
        assert torch.equal(value, final[name]) != name.startswith("nets.0."), name


def test_time_budget_stops_cleanly_and_resume_finishes(data_dir, tmp_path):
    cfg = _config(data_dir, tmp_path / "run")
    cfg.max_seconds = 1e-9  # out of time after the first step
    first = Trainer(cfg)
    assert first.run(progress=False) is None
    info = json.loads((tmp_path / "run" / "run.json").read_text())
    assert (info["scale"], info["step"], info["done"]) == (2, 1, False)
    cfg = _config(data_dir, tmp_path / "run")
    second = Trainer(cfg)
    assert second.resume() and second.run(progress=False).exists()


def test_a_cuda_device_without_cuda_is_a_clear_error(data_dir, tmp_path):
    from agndc_core.errors import AGNDCError

    if torch.cuda.is_available():
        pytest.skip("this machine has CUDA")
    cfg = _config(data_dir, tmp_path / "run")
    cfg.device = "cuda"
    with pytest.raises(AGNDCError, match="CUDA"):
        Trainer(cfg)


def test_dataset_resolution_range(tmp_path, capsys):
    """``--resolutions LO,HI`` draws every shape's longest side from that range."""
    from agndc_core.cli import main
    from agndc_core.errors import AGNDCError

    paths = build_dataset(tmp_path / "a", 3, seed0=5, workers=1, progress=False,
                          resolution_range=(20, 23))
    for path in paths:
        sample = load_sample(path)
        assert 20 <= sample["recipe"]["resolution"] <= 23
        # the voxelised shape spans that many voxels (+ the margins) on its longest side
        assert 20 <= max(sample["lattice"].shape) - 4 <= 23 + 4
    assert main(["train-data", "-o", str(tmp_path / "b"), "-n", "1", "--seed0", "5",
                 "--workers", "1", "--resolutions", "20,23"]) == 0
    assert (tmp_path / "b" / "sample_000005.npz").read_bytes() == paths[0].read_bytes()
    assert main(["train-data", "-o", str(tmp_path / "c"), "-n", "1", "--resolutions", "20"]) != 0
    assert "--resolutions wants LO,HI, got '20'" in capsys.readouterr().err
    assert not (tmp_path / "c").exists()
    with pytest.raises(AGNDCError, match="lo <= hi"):
        build_dataset(tmp_path / "d", 1, resolution_range=(64, 32), progress=False)


@pytest.mark.slow
def test_distilled_samples_take_the_teachers_finest_vertices(data_dir, tmp_path):
    """distil-data: on surface cells vertex0 is the mix of the true and the teacher's vertex
    (the teacher run as remesh runs it); everything else of a sample is unchanged."""
    from agndc_core.checkpoint import default_checkpoint_path
    from agndc_core.inference import predict_lattice
    from agndc_core.pipeline import load_model
    from agndc_core.training.distil import distil_dataset

    teacher = default_checkpoint_path("agndc")
    paths = distil_dataset(data_dir, tmp_path / "half", teacher, weight=0.5, progress=False)
    assert [p.name for p in paths] == sorted(p.name for p in Path(data_dir).glob("*.npz"))
    source, distilled = load_sample(Path(data_dir) / paths[0].name), load_sample(paths[0])
    predicted, _ = predict_lattice(load_model(teacher), source["lattice"], edges=False)
    surface = source["surface0"]
    expected = 0.5 * source["vertex0"][surface] + 0.5 * predicted[surface]
    np.testing.assert_allclose(distilled["vertex0"][surface], expected, atol=1e-6)
    assert np.abs(distilled["vertex0"][surface] - source["vertex0"][surface]).max() > 0.05
    for key in source:
        if key not in ("vertex0", "recipe"):
            np.testing.assert_array_equal(distilled[key], source[key], err_msg=key)
    np.testing.assert_array_equal(distilled["vertex0"][~surface], source["vertex0"][~surface])
    with pytest.raises(AGNDCError, match="teacher weight"):
        distil_dataset(data_dir, tmp_path / "bad", teacher, weight=1.5, progress=False)


def test_a_compiled_step_is_traced_whole_and_trains_as_eager(data_dir, tmp_path):
    """``--compile`` traces each scale's forward + loss and the frozen coarser scales as whole
    graphs (a graph break fails: fullgraph). ``aot_eager`` runs the eager kernels on that
    trace: the same first loss, and the same steps up to the order in which the traced
    replicate padding sums its gradient."""
    runs = {}
    for mode in ("", "aot_eager"):
        cfg = _config(data_dir, tmp_path / (mode or "eager"))
        cfg.compile, cfg.ema = mode, 0.9
        trainer = Trainer(cfg)
        trainer.scale, trainer.optimizer = 0, trainer._optimizer(0)
        trainer.ema = trainer._start_ema(0)
        losses = [float(trainer.train_step(0, step)["loss"]) for step in range(3)]
        runs[mode] = losses, trainer
    (eager_losses, eager), (traced_losses, traced) = runs[""], runs["aot_eager"]
    assert set(traced._compiled_fns) == {("coarser", 0), ("loss", 0)}
    assert eager_losses[0] == traced_losses[0]
    np.testing.assert_allclose(traced_losses, eager_losses, rtol=1e-4)
    for (name, a), b in zip(eager.model.nets[0].state_dict().items(),
                            traced.model.nets[0].state_dict().values()):
        # Adam's normalised steps (3e-3 each) carry the summation order's ~1e-7 as ~1e-6
        torch.testing.assert_close(b, a, rtol=1e-4, atol=1e-5, msg=name)
    for name in eager.ema:
        torch.testing.assert_close(traced.ema[name], eager.ema[name], rtol=1e-4, atol=1e-5)


def test_an_unknown_compile_mode_is_a_clear_error(data_dir, tmp_path):
    cfg = _config(data_dir, tmp_path / "run")
    cfg.compile = "fast"
    with pytest.raises(AGNDCError, match="reduce-overhead"):
        Trainer(cfg)


def test_a_compile_that_fails_trains_on_eagerly_and_says_so(data_dir, tmp_path, monkeypatch):
    """A compiler error at a scale's first step (a GPU machine's window is minutes) falls back
    to eager steps, the same as a run without --compile, and the run's record says so."""
    def broken_compile(fn, **options):
        def compiled(*args, **kwargs):
            raise RuntimeError("no compiler here")
        return compiled

    eager = Trainer(_config(data_dir, tmp_path / "eager"))
    eager.run(progress=False)
    monkeypatch.setattr(train_module.torch, "compile", broken_compile)
    cfg = _config(data_dir, tmp_path / "fallback")
    cfg.compile = "reduce-overhead"
    fallback = Trainer(cfg)
    fallback.run(progress=False)
    for (name, a), b in zip(eager.model.state_dict().items(),
                            fallback.model.state_dict().values()):
        assert torch.equal(a, b), name
    info = json.loads((tmp_path / "fallback" / "run.json").read_text())
    assert info["config"]["compile"] == ""
    assert "no compiler here" in info["sessions"][0]["compile_error"]
    assert "torch.compile" not in info["sessions"][0]["hardware"]
