"""LWSA: Local Window Self-Attention, producing the structural attention map A_s (eq. 12-13).

Swin3D-style: multi-head self-attention inside non-overlapping ``window^3`` windows with a learned
relative position bias, two blocks, the second with windows shifted by half a window.

Interpretation choices (the paper only names Swin3D-Tiny):

* LWSA runs at ``width // attn_div`` channels (a linear projection in) and ends with a
  LayerNorm + linear + sigmoid to the single-channel map A_s that eq. 13 concatenates.
* Windows start at lattice coordinate ``-shift`` and positions outside the lattice repeat the
  nearest lattice point (the same replicate rule as every convolution), instead of Swin's cyclic
  shift with masks: a window's attention then depends only on the lattice around it, never on
  the far side of the grid, which keeps band inference and tiling local.
* Pre-norm blocks (LayerNorm, attention, residual; LayerNorm, MLP, residual) with the
  network-wide LeakyReLU in the MLP; no BatchNorm anywhere.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from .config import AGNDCConfig
from .layout import relative_position_index


class WindowBlock(nn.Module):
    """One (shifted-)window attention block on channel-last features."""

    def __init__(self, dim: int, heads: int, window: int, shift: int, mlp_ratio: int,
                 slope: float):
        super().__init__()
        self.heads, self.window, self.shift, self.slope = heads, window, shift, slope
        self.norm1 = nn.LayerNorm(dim)
        self.qkv = nn.Linear(dim, 3 * dim)
        self.proj = nn.Linear(dim, dim)
        self.norm2 = nn.LayerNorm(dim)
        self.fc1 = nn.Linear(dim, mlp_ratio * dim)
        self.fc2 = nn.Linear(mlp_ratio * dim, dim)
        span = 2 * window - 1
        self.bias_table = nn.Parameter(torch.zeros(span ** 3, heads))
        nn.init.trunc_normal_(self.bias_table, std=0.02)
        # (w^3, w^3) index of the relative offset between tokens i and j into bias_table
        self.register_buffer("bias_index", torch.from_numpy(relative_position_index(window)),
                             persistent=False)

    def forward(self, x: torch.Tensor, ops, radius) -> torch.Tensor:
        qkv = self.qkv(self.norm1(x))
        attended = ops.windows(qkv, self.window, self.shift, self._attend, radius)
        x = ops.crop(x, radius) + self.proj(attended)
        hidden = F.leaky_relu(self.fc1(self.norm2(x)), self.slope, inplace=True)
        return x + self.fc2(hidden)

    def _attend(self, qkv: torch.Tensor) -> torch.Tensor:
        """(W, n, 3 dim) tokens of W windows -> (W, n, dim) attended values."""
        n_win, n, three_dim = qkv.shape
        dim = three_dim // 3
        # (3, W, heads, n, dim / heads)
        q, k, v = qkv.reshape(n_win, n, 3, self.heads, dim // self.heads).permute(2, 0, 3, 1, 4)
        # (1, heads, n, n)
        bias = self.bias_table[self.bias_index].permute(2, 0, 1)[None]
        out = F.scaled_dot_product_attention(q, k, v, attn_mask=bias.to(q.dtype))
        return out.transpose(1, 2).reshape(n_win, n, dim)


class LWSA(nn.Module):
    """Conv features (..., width) -> structural attention map A_s (..., 1) in (0, 1)."""

    def __init__(self, cfg: AGNDCConfig):
        super().__init__()
        dim = cfg.attn_width
        self.proj_in = nn.Linear(cfg.width, dim)
        self.blocks = nn.ModuleList([
            WindowBlock(dim, cfg.heads, cfg.window, shift, cfg.mlp_ratio, cfg.act_slope)
            for shift in (0, cfg.window // 2)
        ])
        self.norm = nn.LayerNorm(dim)
        self.head = nn.Linear(dim, 1)

    def forward(self, f: torch.Tensor, ops, radius) -> torch.Tensor:
        # project on the (narrower) rows f was computed on, then extend to the band
        x = ops.resample(self.proj_in(f), radius)
        for block in self.blocks:
            x = block(x, ops, radius)
        return torch.sigmoid(self.head(self.norm(x)))
