"""The inference runtime without torch: the shipped networks in numpy (``network.py`` over the
band rows of ``band.py``). The CLI, the batch script and the Blender extension run the networks
through it on the CPU; torch stays for training, CUDA inference and as the reference."""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import numpy as np

from ..checkpoint import read_checkpoint_metadata, read_safetensors
from ..errors import ModelError
from .network import Network

__all__ = ["Network", "load_network"]


def load_network(path) -> Network:
    """The numpy ``Network`` of a checkpoint (checked as ``checkpoint.load_checkpoint`` checks
    it; cached per path and modification time)."""
    path = Path(path)
    mtime = path.stat().st_mtime if path.exists() else 0.0
    return _load_cached(str(path), mtime)


@lru_cache(maxsize=4)
def _load_cached(path: str, mtime: float) -> Network:
    weights, _, config = read_checkpoint_metadata(path)
    tensors = read_safetensors(weights)
    bad = [k for k, v in tensors.items() if v.dtype != np.float32]
    if bad:
        raise ModelError(f"{weights}: tensors {', '.join(bad[:4])} are not float32")
    return Network(config, tensors)
