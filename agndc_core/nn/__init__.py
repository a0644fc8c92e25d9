"""The AGNDC networks (torch): config, modules, cascade and loss. Re-exports only."""

from .agdrnet import AGDRNet, AGNDCCascade
from .config import AGNDCConfig, undc_baseline
from .loss import AGNDCLoss

__all__ = ["AGDRNet", "AGNDCCascade", "AGNDCConfig", "AGNDCLoss", "undc_baseline"]
