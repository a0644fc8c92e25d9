"""Self-describing checkpoints: ``<stem>.safetensors`` (weights) + ``<stem>.json`` (the rest).

The JSON sidecar holds ``format_version``, ``model_config`` (``AGNDCConfig.to_dict``), the
parameter count, the training recipe, metrics, and the sha256 of the weights file. Loading never
unpickles: the weights are read with ``safetensors`` (torch) or ``read_safetensors`` (numpy, the
inference runtime), the config with ``json``, and both are checked (hash, keys, shapes) before
the network is built, so a wrong or damaged file gives a ``ModelError`` naming the problem
instead of a broken model. Only ``save_checkpoint`` and ``load_checkpoint`` need torch.
"""

from __future__ import annotations

import hashlib
import json
import struct
from pathlib import Path

import numpy as np

from .errors import ModelError

FORMAT_VERSION = 1
#: folder of the shipped weights (trained separately; may not exist in a fresh checkout)
WEIGHTS_DIR = Path(__file__).resolve().parent / "weights"


def default_checkpoint_path(name: str = "agndc") -> Path:
    """``agndc_core/weights/<name>.safetensors`` (the shipped checkpoint of a method)."""
    return WEIGHTS_DIR / f"{name}.safetensors"


def save_checkpoint(model, path_stem, *, training: dict, metrics: dict) -> Path:
    """Write ``<stem>.safetensors`` and ``<stem>.json``; return the weights path.

    Args:
        model: an ``AGNDCCascade``.
        path_stem: path without suffix (a ``.safetensors``/``.json`` suffix is dropped).
        training: the training recipe (JSON-serialisable: data, steps, optimiser, seeds...).
        metrics: evaluation results (JSON-serialisable).
    """
    from safetensors.torch import save_file

    weights, sidecar = _paths(path_stem)
    state = {k: v.detach().to("cpu").contiguous() for k, v in model.state_dict().items()}
    meta = {
        "format_version": FORMAT_VERSION,
        "model_config": model.config.to_dict(),
        "parameters": count_parameters(model),
        "training": training,
        "metrics": metrics,
        "weights_file": weights.name,
    }
    try:  # fail before writing anything
        json.dumps(meta)
    except TypeError as exc:
        raise ModelError(f"checkpoint metadata is not JSON-serialisable: {exc}") from None
    weights.parent.mkdir(parents=True, exist_ok=True)
    save_file(state, str(weights), metadata={"format": "agndc",
                                             "format_version": str(FORMAT_VERSION)})
    meta["weights_sha256"] = _sha256(weights)
    sidecar.write_text(json.dumps(meta, indent=2, sort_keys=True) + "\n")
    return weights


def load_checkpoint(path):
    """Load a checkpoint written by ``save_checkpoint``.

    Args:
        path: the ``.safetensors`` file, its ``.json`` sidecar, or their common stem.

    Returns:
        (AGNDCCascade in eval mode, metadata dict).

    Raises:
        ModelError: missing files, bad JSON, unknown format version, hash mismatch (corrupt or
        truncated weights), invalid config, missing/unexpected tensors or wrong shapes.
    """
    from safetensors.torch import load_file

    from .nn import AGNDCCascade

    weights, meta, config = read_checkpoint_metadata(path)
    model = AGNDCCascade(config)
    try:
        state = load_file(str(weights))
    except Exception as exc:  # safetensors raises its own errors for malformed files
        raise ModelError(f"cannot read weights {weights}: {exc}") from None
    _check_state(state, model.state_dict(), weights)
    model.load_state_dict(state, strict=True)
    return model.eval(), meta


def read_checkpoint_metadata(path):
    """The checked metadata of a checkpoint, without reading its tensors (no torch).

    Returns:
        (weights path, metadata dict, ``AGNDCConfig``).

    Raises:
        ModelError: missing files, bad JSON, unknown format version, hash mismatch, bad config.
    """
    from .nn.config import AGNDCConfig

    weights, sidecar = _paths(path)
    if not weights.exists():
        if weights == default_checkpoint_path(weights.stem):
            raise ModelError(f"no shipped weights found at {weights}; train with `agndc train` "
                             "or pass --checkpoint")
        raise ModelError(f"checkpoint not found: {weights}")
    if not sidecar.exists():
        raise ModelError(f"checkpoint {weights} has no metadata file {sidecar.name} beside it")
    try:
        meta = json.loads(sidecar.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ModelError(f"cannot read checkpoint metadata {sidecar}: {exc}") from None
    if not isinstance(meta, dict) or meta.get("format_version") != FORMAT_VERSION:
        version = meta.get("format_version") if isinstance(meta, dict) else None
        raise ModelError(f"{sidecar}: unsupported checkpoint format_version {version!r} "
                         f"(this version reads {FORMAT_VERSION})")
    digest = _sha256(weights)
    if digest != meta.get("weights_sha256"):
        raise ModelError(f"{weights} is corrupt or was modified: sha256 {digest[:12]}... does not "
                         f"match the {str(meta.get('weights_sha256'))[:12]}... recorded in "
                         f"{sidecar.name}")
    model_config = meta.get("model_config")
    if isinstance(model_config, dict) and "surface_nets_prior" not in model_config:
        # written before the prior existed: those networks predict absolute offsets
        model_config = {**model_config, "surface_nets_prior": False}
    return weights, meta, AGNDCConfig.from_dict(model_config)


#: safetensors dtype names -> numpy dtypes (the checkpoints hold float32 only)
_SAFETENSORS_DTYPES = {"F32": np.float32, "F64": np.float64, "F16": np.float16,
                       "I64": np.int64, "I32": np.int32}


def read_safetensors(path) -> dict[str, np.ndarray]:
    """All tensors of a ``.safetensors`` file as numpy arrays (the format: an 8-byte
    little-endian header length, a JSON header of dtype, shape and byte range per tensor, then
    the raw little-endian data). Raises ModelError on a malformed file."""
    path = Path(path)
    try:
        data = path.read_bytes()
        (n,) = struct.unpack("<Q", data[:8])
        header = json.loads(data[8:8 + n])
        tensors = {}
        for name, info in header.items():
            if name == "__metadata__":
                continue
            begin, end = info["data_offsets"]
            dtype = np.dtype(_SAFETENSORS_DTYPES[info["dtype"]]).newbyteorder("<")
            count = int(np.prod(info["shape"], dtype=np.int64))
            if end - begin != count * dtype.itemsize or 8 + n + end > len(data):
                raise ValueError(f"tensor {name}: byte range does not match its shape")
            array = np.frombuffer(data, dtype=dtype, count=count, offset=8 + n + begin)
            tensors[name] = array.astype(dtype.newbyteorder("="), copy=True).reshape(info["shape"])
    except (OSError, ValueError, KeyError, TypeError, struct.error) as exc:
        raise ModelError(f"cannot read weights {path}: {exc}") from None
    return tensors


def _check_state(state: dict, expected: dict, weights: Path) -> None:
    missing = sorted(set(expected) - set(state))
    unexpected = sorted(set(state) - set(expected))
    wrong = [f"{k} {tuple(state[k].shape)} != {tuple(v.shape)}" for k, v in expected.items()
             if k in state and tuple(state[k].shape) != tuple(v.shape)]
    problems = []
    if missing:
        problems.append(f"missing tensors {_few(missing)}")
    if unexpected:
        problems.append(f"unexpected tensors {_few(unexpected)}")
    if wrong:
        problems.append(f"wrong shapes {_few(wrong)}")
    if problems:
        raise ModelError(f"{weights} does not match its model_config: " + "; ".join(problems))
    for k, v in state.items():
        if v.dtype != expected[k].dtype:
            raise ModelError(f"{weights}: tensor {k} has dtype {v.dtype}, expected "
                             f"{expected[k].dtype}")


def _few(items: list, n: int = 4) -> str:
    return ", ".join(items[:n]) + (f" (+{len(items) - n} more)" if len(items) > n else "")


def _paths(path) -> tuple[Path, Path]:
    path = Path(path)
    stem = path.with_suffix("") if path.suffix in (".safetensors", ".json") else path
    return stem.with_name(stem.name + ".safetensors"), stem.with_name(stem.name + ".json")


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def count_parameters(model) -> int:
    """Number of learnable parameters."""
    return int(sum(p.numel() for p in model.parameters()))
