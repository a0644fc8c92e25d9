"""FDM: Feature Decomposition Module (paper eq. 15): three 3x3x3 convs and a 2-layer MLP head.

    P'_s = MLP(Conv3d^3(F_s))         6 channels: vertex offsets (0..2), edge logits (3..5)

The MLP is two 1x1x1 convs (``nn.Linear`` on channel-last features). ``PredictionHead`` is
shared with CRPM; its edge-logit bias starts at the log-odds of ``EDGE_PRIOR`` (few lattice edges
are crossed), so an untrained network predicts "no surface" far from the surface instead of
random topology, and far-field sparse up-sampling is empty from the first step.

Band evaluation: the convs shrink towards the output radius (conv i at ``radius + 2 - i``).
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn

from .config import AGNDCConfig

#: prior probability of a crossed lattice edge, for the edge-logit bias at initialisation
EDGE_PRIOR = 0.05


class PredictionHead(nn.Module):
    """(..., c) -> (..., 6): Linear, LeakyReLU, Linear (two fully connected layers)."""

    def __init__(self, c: int, slope: float):
        super().__init__()
        self.fc1 = nn.Linear(c, c)
        self.fc2 = nn.Linear(c, 6)
        self.slope = slope
        self.reset_edge_prior()

    @torch.no_grad()
    def reset_edge_prior(self) -> None:
        """Edge-logit biases to the log-odds of EDGE_PRIOR."""
        self.fc2.bias[3:] = math.log(EDGE_PRIOR / (1 - EDGE_PRIOR))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.fc2(F.leaky_relu(self.fc1(x), self.slope, inplace=True))


class FDM(nn.Module):
    """(..., width) features -> (..., 6) isolated prediction P'_s."""

    def __init__(self, cfg: AGNDCConfig):
        super().__init__()
        c = cfg.width
        self.slope = cfg.act_slope
        self.convs = nn.ModuleList([nn.Conv3d(c, c, 3) for _ in range(3)])
        self.head = PredictionHead(c, cfg.act_slope)

    def forward(self, f: torch.Tensor, ops, radius) -> torch.Tensor:
        x = f
        for i, conv in enumerate(self.convs):
            x = ops.conv(x, conv, min(ops.radius, radius + 2 - i))
            x = F.leaky_relu(x, self.slope, inplace=True)
        return self.head(x)
