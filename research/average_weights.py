"""Checkpoints averaged weight by weight (a "model soup"): one self-describing checkpoint whose
every tensor is the mean of the same tensor in two or more checkpoints of one architecture.

Continuations of one network with different seeds (the same start, a small learning rate) stay
in one basin, where the mean of their weights is itself a network and often a better one than
each; it costs nothing at inference:

    .venv/bin/python research/average_weights.py A.safetensors B.safetensors -o runs/soup/ab

The recipe written in the new checkpoint's sidecar names each source, its sha256 and its own
recipe (steps, seeds, the lineage's hardware), so the soup stays traceable.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import torch

from agndc_core.checkpoint import load_checkpoint, read_checkpoint_metadata, save_checkpoint
from agndc_core.errors import ModelError


def average_models(paths: list[Path], weights: list[float] | None = None):
    """(the first checkpoint's model holding the weighted mean of all the checkpoints' tensors,
    their metadata). ``weights`` default to equal; they are normalised to sum to 1."""
    if len(paths) < 2:
        raise ModelError("averaging needs at least two checkpoints")
    weights = [1.0] * len(paths) if weights is None else list(weights)
    if len(weights) != len(paths) or min(weights) < 0 or sum(weights) <= 0:
        raise ModelError("one non-negative weight per checkpoint, not all zero")
    total = sum(weights)
    models, metas = zip(*(load_checkpoint(path) for path in paths), strict=True)
    configs = [meta["model_config"] for meta in metas]
    if any(config != configs[0] for config in configs[1:]):
        raise ModelError("the checkpoints hold different architectures; cannot average them")
    states = [model.state_dict() for model in models]
    mean = {}
    for key, tensor in states[0].items():
        if tensor.is_floating_point():
            mean[key] = sum(w / total * state[key].double() for w, state in
                            zip(weights, states, strict=True)).to(tensor.dtype)
        else:  # counters and the like: the first checkpoint's
            mean[key] = tensor
    model = models[0]
    model.load_state_dict(mean, strict=True)
    return model, list(metas)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("checkpoints", nargs="+", type=Path)
    parser.add_argument("-o", "--out", required=True, type=Path,
                        help="the new checkpoint's path stem")
    parser.add_argument("--weights", default=None,
                        help="comma-separated share of each checkpoint (default: equal)")
    args = parser.parse_args()
    weights = None if args.weights is None else [float(w) for w in args.weights.split(",")]
    with torch.no_grad():
        model, metas = average_models(args.checkpoints, weights)
    sources = [{"checkpoint": str(path), "weights_sha256": meta.get("weights_sha256"),
                "training": meta.get("training")}
               for path, meta in zip(args.checkpoints, metas, strict=True)]
    shares = weights or [1.0] * len(sources)
    path = save_checkpoint(model, args.out, metrics={}, training={
        "recipe": "weight average", "shares": [w / sum(shares) for w in shares],
        "sources": sources})
    read_checkpoint_metadata(path)  # written and readable
    print(path)


if __name__ == "__main__":
    main()
