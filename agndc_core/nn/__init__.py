"""The AGNDC networks (torch): config, modules, cascade and loss. Re-exports only.

The re-exports are resolved on first use, so ``agndc_core.nn.config`` and ``agndc_core.nn.layout``
(numpy only, read by the torch-free inference runtime) import without torch.
"""

from importlib import import_module

_EXPORTS = {"AGDRNet": "agdrnet", "AGNDCCascade": "agdrnet", "AGNDCConfig": "config",
            "undc_baseline": "config", "AGNDCLoss": "loss"}

__all__ = list(_EXPORTS)


def __getattr__(name):
    if name in _EXPORTS:
        return getattr(import_module(f".{_EXPORTS[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
