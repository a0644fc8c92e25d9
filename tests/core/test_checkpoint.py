"""Checkpoints: bit-exact round trip, never unpickled, corruption detected."""

import json
import pickle

import numpy as np
import pytest
import torch

from agndc_core.checkpoint import default_checkpoint_path, load_checkpoint, save_checkpoint
from agndc_core.errors import ModelError
from agndc_core.nn import AGNDCCascade, AGNDCConfig


@pytest.fixture()
def saved(tmp_path):
    torch.manual_seed(1)
    model = AGNDCCascade(AGNDCConfig(width=8, levels=1))
    path = save_checkpoint(model, tmp_path / "net", training={"steps": 3, "lr": 1e-3},
                           metrics={"cd": 9.0})
    return model, path


def test_round_trip_is_bit_exact(saved, monkeypatch):
    model, path = saved
    # loading must never unpickle
    for module, name in ((pickle, "load"), (pickle, "loads"), (torch, "load")):
        monkeypatch.setattr(module, name, lambda *a, **k: pytest.fail("unpickled"))
    loaded, meta = load_checkpoint(path)
    assert meta["model_config"] == model.config.to_dict()
    assert meta["training"] == {"steps": 3, "lr": 1e-3} and meta["metrics"] == {"cd": 9.0}
    assert meta["parameters"] == sum(p.numel() for p in model.parameters())
    a, b = model.state_dict(), loaded.state_dict()
    assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)
    g = torch.zeros(1, 16, 16, 16)
    g[0, 4:11, 5:12, 3:9] = 1
    with torch.no_grad():
        assert all(torch.equal(p, q) for p, q in zip(model.eval()(g), loaded(g)))
    assert not loaded.training


def test_load_accepts_stem_and_sidecar(saved):
    _, path = saved
    load_checkpoint(path.with_suffix(""))
    load_checkpoint(path.with_suffix(".json"))


def test_corrupt_weights_are_refused(saved):
    _, path = saved
    data = bytearray(path.read_bytes())
    data[-10] ^= 0xFF
    path.write_bytes(bytes(data))
    with pytest.raises(ModelError, match="corrupt"):
        load_checkpoint(path)


def test_truncated_weights_are_refused(saved):
    _, path = saved
    path.write_bytes(path.read_bytes()[:1000])
    with pytest.raises(ModelError, match="corrupt"):
        load_checkpoint(path)


def test_truncated_weights_with_matching_hash_are_refused(saved):
    _, path = saved
    path.write_bytes(path.read_bytes()[:1000])
    _rewrite_meta(path, lambda m: m.update(weights_sha256=_sha(path)))
    with pytest.raises(ModelError, match="cannot read weights"):
        load_checkpoint(path)


def test_config_mismatch_names_the_tensors(saved):
    _, path = saved
    _rewrite_meta(path, lambda m: m["model_config"].update(width=16))
    with pytest.raises(ModelError, match="wrong shapes"):
        load_checkpoint(path)
    _rewrite_meta(path, lambda m: m["model_config"].update(width=8, levels=0))
    with pytest.raises(ModelError, match="unexpected tensors"):
        load_checkpoint(path)


def test_bad_metadata(saved):
    _, path = saved
    _rewrite_meta(path, lambda m: m.update(format_version=99))
    with pytest.raises(ModelError, match="format_version"):
        load_checkpoint(path)
    path.with_suffix(".json").write_text("{not json")
    with pytest.raises(ModelError, match="metadata"):
        load_checkpoint(path)
    path.with_suffix(".json").unlink()
    with pytest.raises(ModelError, match="no metadata"):
        load_checkpoint(path)


def test_missing_files(tmp_path):
    with pytest.raises(ModelError, match="not found"):
        load_checkpoint(tmp_path / "nothing.safetensors")
    name = "no_such_model_for_tests"
    assert default_checkpoint_path(name).name == f"{name}.safetensors"
    with pytest.raises(ModelError, match="no shipped weights found at .*agndc train"):
        load_checkpoint(default_checkpoint_path(name))


def test_unserialisable_metadata(tmp_path):
    model = AGNDCCascade(AGNDCConfig(width=8, levels=0))
    with pytest.raises(ModelError, match="JSON"):
        save_checkpoint(model, tmp_path / "x", training={"array": np.zeros(2)}, metrics={})
    assert not (tmp_path / "x.safetensors").exists()


def _rewrite_meta(path, change):
    sidecar = path.with_suffix(".json")
    meta = json.loads(sidecar.read_text())
    change(meta)
    sidecar.write_text(json.dumps(meta))


def _sha(path):
    import hashlib

    return hashlib.sha256(path.read_bytes()).hexdigest()
