"""DSConv: dynamic snake convolution (Qi et al., ICCV 2023, "DSCNet"), in 3-D.

Four branches on the same input, concatenated and fused by a 1x1x1 conv:

* a plain 3x3x3 conv;
* three snakes, one per axis. A snake along x has K taps on the lattice points x - K//2 .. x + K//2
  whose y and z positions drift: tap c +- i sits at the *cumulative* sum of the bounded drifts of
  taps c +- 1 .. c +- i (``common.snake_offsets``), so the kernel bends continuously while the
  centre tap stays put. Because the taps stay on integer x, a tap interpolates bilinearly in y
  and z only (4 corners, gathered), never a 3-D ``grid_sample``.

A snake branch is DSCNet's K x 1 x 1 conv with stride K over the K sampled taps:
``sum_t W_t sample_t(x)``. Sampling is linear, so this equals ``sum_t sample_t(W_t x)``; we project
first (one ``nn.Linear`` to K x branch width) and then gather the narrow projected rows, which
moves ``in_channels / branch_width`` times less memory than gathering the input.

Interpretation choices: the drifts are predicted by a 1x1x1 conv from the plain branch's output
(so the offset predictor is a small 3x3x3 + 1x1x1 conv stack sharing the plain branch's work),
``tanh``-bounded and scaled by the extend scope; branches are ``width // snake_div`` channels
wide; LeakyReLU after every branch and after the fusion, no normalisation.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from .common import snake_offsets
from .config import AGNDCConfig


class DSConv(nn.Module):
    """(..., c_in) -> (..., c_out) dynamic snake convolution on channel-last features."""

    def __init__(self, c_in: int, c_out: int, cfg: AGNDCConfig):
        super().__init__()
        width, self.kernel = cfg.snake_width, cfg.snake_kernel
        self.scope, self.slope = cfg.snake_scope, cfg.act_slope
        self.plain = nn.Conv3d(c_in, width, 3)
        # per position: 3 snakes x 2 lateral axes x K drifts
        self.offset = nn.Linear(width, 3 * 2 * self.kernel)
        # per snake: the K taps' weights of DSCNet's K x 1 x 1 conv, applied before sampling
        self.taps = nn.ModuleList([nn.Linear(c_in, self.kernel * width) for _ in range(3)])
        self.fuse = nn.Linear(4 * width, c_out)

    def forward(self, x: torch.Tensor, ops, radius) -> torch.Tensor:
        plain = F.leaky_relu(ops.conv(x, self.plain, radius), self.slope, inplace=True)
        # (..., 3, 2, K) cumulative lateral offsets of each snake's taps
        drift = self.offset(plain).unflatten(-1, (3, 2, self.kernel))
        offsets = snake_offsets(drift, self.scope)
        branches = [plain]
        for axis, taps in enumerate(self.taps):
            snake = ops.snake(taps(x), offsets[..., axis, :, :], axis, radius)
            branches.append(F.leaky_relu(snake, self.slope, inplace=True))
        return F.leaky_relu(self.fuse(torch.cat(branches, -1)), self.slope, inplace=True)


class PlainConv(nn.Module):
    """The ``use_snake=False`` stand-in for DSConv: one 3x3x3 conv + LeakyReLU."""

    def __init__(self, c_in: int, c_out: int, cfg: AGNDCConfig):
        super().__init__()
        self.conv = nn.Conv3d(c_in, c_out, 3)
        self.slope = cfg.act_slope

    def forward(self, x: torch.Tensor, ops, radius) -> torch.Tensor:
        return F.leaky_relu(ops.conv(x, self.conv, radius), self.slope, inplace=True)
