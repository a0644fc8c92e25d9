"""DFFM: Dynamic Feature Fusion Module (paper Sec. 3.2.2, eq. 16-21).

    F^m    = Conv3d(U_s)                                      3x3x3, 6 -> width      (16)
    A^ch   = sigmoid(Conv_att(AvgPool(Concat(F_s, F^m))))    1x1x1 convs 2w -> w/2 -> 2w (17)
    F^red  = Conv_red(Concat(F_s, F^m) * A^ch)               1x1x1, 2w -> w          (18)
    A^sp   = sigmoid(Conv_1(F_s) + Conv_2(F^m))              3x3x3, w -> 1 each      (19-20)
    W_s    = Conv3d(F^red * A^sp)                             3x3x3, w -> 6           (21)

Interpretation: CBAM/SE-style channel attention pools globally, which would make every point
depend on the whole grid (its padding, the tile it is in). We pool *locally*: the mean over the
2x2x2 block of the next coarser lattice, broadcast back (``ops.down`` then ``ops.up``), so the
gate sees a point's block context and band inference and tiling stay exact.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from .config import AGNDCConfig


class DFFM(nn.Module):
    """(F_s (..., w), coarser prediction) -> fused sparse prediction W_s (..., 6)."""

    def __init__(self, cfg: AGNDCConfig):
        super().__init__()
        c = cfg.width
        self.slope = cfg.act_slope
        self.embed = nn.Conv3d(6, c, 3)
        self.att1 = nn.Linear(2 * c, c // 2)
        self.att2 = nn.Linear(c // 2, 2 * c)
        self.reduce = nn.Linear(2 * c, c)
        self.spatial_f = nn.Conv3d(c, 1, 3)
        self.spatial_m = nn.Conv3d(c, 1, 3)
        self.out = nn.Conv3d(c, 6, 3)

    def forward(self, f: torch.Tensor, p_coarser: torch.Tensor, ops, radius) -> torch.Tensor:
        # radii that keep every read inside what was computed (capped by the band)
        r1 = min(ops.radius, radius + 1)  # the gated features
        r2 = min(ops.radius, radius + 3)  # F^m and the concat: r1 + the 2x2x2 block's reach
        u = ops.upsample_prediction(p_coarser, min(ops.radius, radius + 4))
        f_m = F.leaky_relu(ops.conv(u, self.embed, r2), self.slope, inplace=True)
        both = torch.cat([ops.crop(f, r2), f_m], -1)
        # local average pool (the 2x2x2 block mean, broadcast back) of the concat, then Conv_att;
        # its first 1x1x1 conv is linear, so it is applied before the pool: 4x fewer channels
        hidden = ops.up(ops.down(self.att1(both), min(ops.half.radius, (r1 + 1) // 2)), r1)
        gate = torch.sigmoid(self.att2(F.leaky_relu(hidden, self.slope)))
        reduced = F.leaky_relu(self.reduce(ops.crop(both, r1) * gate), self.slope, inplace=True)
        spatial = torch.sigmoid(ops.conv(f, self.spatial_f, r1) + ops.conv(f_m, self.spatial_m, r1))
        return ops.conv(reduced * spatial, self.out, radius)
