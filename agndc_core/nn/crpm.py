"""CRPM: Contour Refinement Postprocess Module (paper Sec. 3.2.3, eq. 22-24).

    F^1 = Conv3d(Concat(W_s, P'_s))                        3x3x3, 12 -> w               (22)
    F^2 = Up(Conv3d^3(Down(F^1)))                          three 3x3x3 at half res      (23)
    P_s = MLP(Conv3d^2(Concat(F^1, F^2)))                  3x3x3 2w -> w, w -> w; MLP   (24)

Interpretation: Down is the 2x2x2 block mean, Up nearest-neighbour (parameter-free, so the module
stays as small as the paper describes; the three half-resolution convs do the learning).

Band evaluation: the half-resolution convs run on ``ops.half``, a band of the coarser lattice
derived from this scale's band; the last two convs shrink to the output radius.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from .config import AGNDCConfig
from .fdm import PredictionHead
from .layout import crpm_radii


class CRPM(nn.Module):
    """(W_s (..., 6), P'_s (..., 6)) -> final prediction P_s (..., 6)."""

    def __init__(self, cfg: AGNDCConfig):
        super().__init__()
        c = cfg.width
        self.slope = cfg.act_slope
        self.aggregate = nn.Conv3d(12, c, 3)
        self.inner = nn.ModuleList([nn.Conv3d(c, c, 3) for _ in range(3)])
        self.mix = nn.ModuleList([nn.Conv3d(2 * c, c, 3), nn.Conv3d(c, c, 3)])
        self.head = PredictionHead(c, cfg.act_slope)

    @staticmethod
    def radii(radius: int) -> dict:
        """Band radii of each stage for an output of ``radius``, so that no read leaves what
        was computed (before capping by the band): mix convs, F^1/F^2, half-res stages."""
        return crpm_radii(radius)

    def forward(self, w: torch.Tensor, p_iso: torch.Tensor, ops, radius) -> torch.Tensor:
        act = lambda x: F.leaky_relu(x, self.slope, inplace=True)  # noqa: E731  (fresh tensors)
        r = {k: min(ops.radius, v) for k, v in self.radii(radius).items()}
        half = ops.half
        r_half = min(half.radius, self.radii(radius)["half"])
        r_down = min(half.radius, self.radii(radius)["down"])
        both = torch.cat([ops.crop(w, r["input"]), ops.crop(p_iso, r["input"])], -1)
        f1 = act(ops.conv(both, self.aggregate, r["f1"]))
        x = ops.down(f1, r_down)
        for i, conv in enumerate(self.inner):
            x = act(half.conv(x, conv, max(r_half, r_down - 1 - i)))
        f2 = ops.up(x, r["f"])
        x = act(ops.conv(torch.cat([ops.crop(f1, r["f"]), f2], -1), self.mix[0], r["mix"]))
        x = act(ops.conv(x, self.mix[1], radius))
        return self.head(x)
