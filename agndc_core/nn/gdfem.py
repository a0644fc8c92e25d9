"""GDFEM: Global-Dynamic Feature Extraction Module (paper Sec. 3.2.1, eq. 12-14).

    f    = Conv3d^3(G_s)                      three 3x3x3 convs, 1 -> width channels
    A_s  = LWSA(f)                            (attention.py), one channel
    F^A  = Concat(A_s, f)                     width + 1 channels
    F_s  = DS(DS(DS(F^A) + F^A) + F^A)        (snake.py); the last DSConv maps to width

With ``use_attention=False`` F^A = f; with ``use_snake=False`` the DSConvs are plain 3x3x3 convs.

Band evaluation: the three convs see a receptive field of 1, 2, 3 points, so they are computed on
bands of radius 1, 2, 3 (points farther from the surface are exactly the far values); the rest
runs on the full band.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from .attention import LWSA
from .config import AGNDCConfig
from .snake import DSConv, PlainConv


class GDFEM(nn.Module):
    """(..., 1) occupancy -> (..., width) dynamic features F_s."""

    def __init__(self, cfg: AGNDCConfig):
        super().__init__()
        c = cfg.width
        self.slope = cfg.act_slope
        self.convs = nn.ModuleList([nn.Conv3d(1, c, 3), nn.Conv3d(c, c, 3), nn.Conv3d(c, c, 3)])
        self.lwsa = LWSA(cfg) if cfg.use_attention else None
        c_a = c + (1 if cfg.use_attention else 0)
        block = DSConv if cfg.use_snake else PlainConv
        self.dynamic = nn.ModuleList([block(c_a, c_a, cfg), block(c_a, c_a, cfg),
                                      block(c_a, c, cfg)])

    def forward(self, g: torch.Tensor, ops, radius) -> torch.Tensor:
        f = g
        for i, conv in enumerate(self.convs):
            f = F.leaky_relu(ops.conv(f, conv, min(i + 1, radius)), self.slope, inplace=True)
        f_a = ops.resample(f, radius)
        if self.lwsa is not None:
            f_a = torch.cat([self.lwsa(f, ops, radius), f_a], -1)
        first, second, last = self.dynamic
        x = first(f_a, ops, radius) + f_a
        x = second(x, ops, radius) + f_a
        return last(x, ops, radius)
