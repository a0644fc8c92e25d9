"""AGDRNet per scale and the AGNDC cascade (paper Sec. 3.1-3.2, eq. 2-11).

    P_j = AGDRNet*(G_j)          = FDM(GDFEM(G_j))                                  (2, 10-11)
    P_s = AGDRNet(G_s, P_{s+1})  = CRPM(DFFM(F_s, u(P_{s+1})), FDM(F_s)),  F_s = GDFEM(G_s)  (3-9)

G_s is the padded dual-contouring lattice (grid.py) OR-pooled s times; every P_s is
(B, 6, X_s, Y_s, Z_s): channels 0..2 the dual vertex of the cell at that point as an offset
(trained towards [0, 1]^3), channels 3..5 the logits of the edges leaving the point along +x, +y,
+z. Ablations: without DFFM, W_s = U_s = u(P_{s+1}); without CRPM, P_s = P'_s + W_s.

Inside the modules features are channel-last and spatial work goes through an ``ops`` object
(``DenseOps`` for training and the reference, ``BandOps`` for fast inference); ``radius`` is the
band radius a module's output is needed on (ignored by ``DenseOps``).
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from ..errors import ModelError
from ..grid import occupancy_pyramid
from ..surfacenets import CENTRE
from .band_ops import BandOps, scale_ops, torus_periods
from .common import surface_nets_offsets
from .config import AGNDCConfig
from .crpm import CRPM
from .dense_ops import DenseOps
from .dffm import DFFM
from .fdm import FDM, PredictionHead
from .gdfem import GDFEM
from .layout import lookup_margin
from .snake import DSConv


class AGDRNet(nn.Module):
    """The network of one scale; ``coarsest=True`` makes it AGDRNet* (no coarser input)."""

    def __init__(self, cfg: AGNDCConfig, coarsest: bool):
        super().__init__()
        self.coarsest = coarsest
        self.gdfem = GDFEM(cfg)
        self.fdm = FDM(cfg)
        self.dffm = DFFM(cfg) if cfg.use_dffm and not coarsest else None
        self.crpm = CRPM(cfg) if cfg.use_crpm and not coarsest else None

    def forward(self, g, p_coarser, ops, radius) -> torch.Tensor:
        """Channel-last occupancy ``g`` (+ coarser prediction) -> (..., 6) prediction."""
        f = self.gdfem(ops.input(g), ops, ops.radius)
        if self.coarsest:
            return self.fdm(f, ops, radius)
        r_w = radius if self.crpm is None else min(ops.radius, CRPM.radii(radius)["input"])
        p_iso = self.fdm(f, ops, r_w)
        if self.dffm is not None:
            w = self.dffm(f, p_coarser, ops, r_w)
        else:
            w = ops.upsample_prediction(p_coarser, r_w)
        if self.crpm is not None:
            return self.crpm(w, p_iso, ops, radius)
        return ops.crop(p_iso, radius) + ops.crop(w, radius)


class AGNDCCascade(nn.Module):
    """One AGDRNet per scale s = 0..levels (index s); ``nets[levels]`` is AGDRNet*."""

    def __init__(self, config: AGNDCConfig | None = None):
        super().__init__()
        self.config = config or AGNDCConfig()
        levels = self.config.levels
        self.nets = nn.ModuleList([AGDRNet(self.config, coarsest=(s == levels))
                                   for s in range(levels + 1)])
        self.apply(self._init_weights)
        self._init_outputs()

    def _init_weights(self, module: nn.Module) -> None:
        """He-normal weights for the LeakyReLU stacks (signals neither vanish nor explode with
        depth), zero biases, and the edge-logit prior of the prediction heads."""
        if isinstance(module, (nn.Conv3d, nn.Linear)):
            nn.init.kaiming_normal_(module.weight, a=self.config.act_slope,
                                    nonlinearity="leaky_relu")
            if module.bias is not None:
                nn.init.zeros_(module.bias)
        if isinstance(module, PredictionHead):
            module.reset_edge_prior()

    @torch.no_grad()
    def _init_outputs(self, root: nn.Module | None = None, snakes: bool = True) -> None:
        """Start every scale's vertex output at the cell centre (the surface nets vertex once
        the prior is added) and every snake straight, as deformable-convolution practice does
        for offsets: a randomly bent kernel or a random vertex is pure noise that the first
        thousand steps would only spend undoing. ``root``: only its modules (e.g. one scale's
        net, to restart a warm-started network's vertex output).

        Only the *last* layer on each path to the vertex output starts at zero. With CRPM the
        output is CRPM's head, which sees the trunk only through P'_s and W_s (12 channels,
        eq. 22): zeroing their vertex rows too would put two zero layers in series, each one's
        gradient proportional to the other's weights. Their vertex rows keep their random
        start and carry the trunk's features into CRPM, as the edge rows do, and a warm
        restart keeps what they learned. (Measured from scratch: no change in 600 steps; the
        stall of that run was the targets' layer noise,
        docs/experiments/binary-targets-curriculum.md.)"""
        root = root or self
        nets = [root] if isinstance(root, AGDRNet) else [m for m in root.modules()
                                                           if isinstance(m, AGDRNet)]
        for net in nets:
            head = net.fdm.head if net.crpm is None else net.crpm.head
            head.fc2.weight[:3] = 0.0
            head.fc2.bias[:3] = CENTRE
            if net.crpm is None and net.dffm is not None:
                net.dffm.out.weight[:3] = 0.0  # W_s's vertex part is added to P'_s without CRPM
                net.dffm.out.bias[:3] = 0.0
        if snakes:
            for module in root.modules():
                if isinstance(module, DSConv):
                    module.offset.weight.zero_()
                    module.offset.bias.zero_()

    def add_prior(self, p0: torch.Tensor, occupancy0) -> torch.Tensor:
        """P_0 (..., X, Y, Z, 6) channel-last + the surface nets prior of its occupancy.

        The prior is the *delta* from the cell centre (zero in cells with no crossed edge), so
        the far field of band inference is unchanged. Identity without ``surface_nets_prior``.
        """
        if not self.config.surface_nets_prior:
            return p0
        if isinstance(occupancy0, np.ndarray):
            occupancy0 = torch.from_numpy(np.ascontiguousarray(occupancy0))
        delta = surface_nets_offsets(occupancy0.to(p0.device)) - CENTRE
        # (..., X, Y, Z, 6): no prior on the edge logits
        return p0 + F.pad(delta, (0, 3)).to(p0.dtype)

    @property
    def levels(self) -> int:
        return self.config.levels

    @property
    def torus_periods(self) -> list[int]:
        """Far-field period of each scale (band inference, ``band_ops.torus_periods``)."""
        return torus_periods(self.levels, self.config.window if self.config.use_attention
                             else None)

    def forward_scale(self, s: int, g_s: torch.Tensor, p_coarser: torch.Tensor | None = None):
        """P_s from G_s (and P_{s+1}): one scale alone, e.g. for per-scale training.

        Args:
            s: scale index, 0 (finest) .. levels (coarsest).
            g_s: (B, X, Y, Z) or (B, 1, X, Y, Z) occupancy (bool or 0/1 float) of scale s.
            p_coarser: (B, 6, X/2, Y/2, Z/2) prediction of scale s+1; None for s == levels.

        Returns:
            (B, 6, X, Y, Z) prediction P_s (raw vertex offsets and edge logits).
        """
        if not 0 <= s <= self.levels:
            raise ModelError(f"scale {s} out of range 0..{self.levels}")
        g_s = _occupancy(g_s)
        coarse = None
        if s < self.levels:
            if p_coarser is None:
                raise ModelError(f"scale {s} needs the prediction of scale {s + 1}")
            want = (g_s.shape[0], 6, *(n // 2 for n in g_s.shape[1:]))
            if tuple(p_coarser.shape) != want or any(n % 2 for n in g_s.shape[1:]):
                raise ModelError(f"scale {s}: coarser prediction must be {want} for a lattice "
                                 f"of {tuple(g_s.shape[1:])}, got {tuple(p_coarser.shape)}")
            # (B, X/2, Y/2, Z/2, 6)
            coarse = p_coarser.permute(0, 2, 3, 4, 1)
        out = self.nets[s](g_s, coarse, DenseOps(g_s.shape[1:]), 0)
        if s == 0:
            out = self.add_prior(out, g_s)
        # (B, 6, X, Y, Z)
        return out.permute(0, 4, 1, 2, 3)

    def forward(self, g0: torch.Tensor) -> list[torch.Tensor]:
        """Whole cascade on the finest lattice, dense.

        Args:
            g0: (B, X, Y, Z) or (B, 1, X, Y, Z) occupancy; X, Y, Z multiples of 2**levels.

        Returns:
            [P_0, ..., P_levels], P_s of shape (B, 6, X/2^s, Y/2^s, Z/2^s).
        """
        grids = [_occupancy(g0)]
        step = 2 ** self.levels
        if any(n % step for n in grids[0].shape[1:]):
            raise ModelError(f"lattice {tuple(grids[0].shape[1:])} must have every side a "
                             f"multiple of {step} for {self.levels} levels (grid.pad_to_lattice)")
        for _ in range(self.levels):
            # (B, X/2, Y/2, Z/2): OR-pooling of the binary occupancy
            grids.append(F.max_pool3d(grids[-1][:, None], 2)[:, 0])
        preds = [None] * (self.levels + 1)
        p = None
        for s in reversed(range(self.levels + 1)):
            p = preds[s] = self.forward_scale(s, grids[s], p)
        return preds

    def band_scale(self, s: int, occupancy_s, coarser=None, radius: int | None = None,
                   out_radius: int | None = None):
        """Band evaluation of scale s on one lattice (``band_ops``): the fast inference path.

        Args:
            s: scale index.
            occupancy_s: (X, Y, Z) bool numpy lattice of scale s.
            coarser: None for s == levels, else (P_{s+1} (X/2, Y/2, Z/2, 6) channel-last
                tensor, its torus rows (T, 6)) as returned by the coarser scale.
            radius: band radius (default ``config.band_radius``); out_radius: radius the
                output is needed on (default: the band radius).

        Returns:
            (rows (R, 6) of the output, the scale's BandOps); ``ops.to_dense(rows)`` is the
            (X, Y, Z, 6) prediction, ``rows[:ops.torus]`` its far-field rows.
        """
        cfg = self.config
        radius = cfg.band_radius if radius is None else radius
        periods = self.torus_periods
        margin = lookup_margin(cfg.snake_kernel, cfg.snake_scope, cfg.window)
        device = next(self.parameters()).device
        ops = scale_ops(occupancy_s, radius, periods[s],
                        periods[s + 1] if s < self.levels else None, margin, device)
        p_rows = None
        if s < self.levels:
            if coarser is None:
                raise ModelError(f"scale {s} needs the prediction of scale {s + 1}")
            p_dense, p_torus = coarser
            ops.coarser = BandOps.everywhere(p_dense.shape[:3], periods[s + 1], device)
            if p_torus.shape[0] != ops.coarser.torus:
                raise ModelError(f"scale {s}: coarser torus rows {tuple(p_torus.shape)} do not "
                                 f"match period {periods[s + 1]}")
            p_rows = torch.cat([p_torus, p_dense.reshape(-1, 6)])
        rows = self.nets[s](None, p_rows, ops, radius if out_radius is None else out_radius)
        return rows, ops

    def forward_band(self, lattice, radius: int | None = None) -> list[torch.Tensor]:
        """Whole cascade by band evaluation (differentiable, so it can also be trained).

        Args:
            lattice: (X, Y, Z) bool numpy lattice, sides multiples of 2**levels.

        Returns:
            [P_0, ..., P_levels] channel-last (X_s, Y_s, Z_s, 6); far from the surface (beyond
            the band) each holds the far-field value.
        """
        grids = occupancy_pyramid(lattice, self.levels)
        preds, coarser = [None] * (self.levels + 1), None
        for s in reversed(range(self.levels + 1)):
            rows, ops = self.band_scale(s, grids[s], coarser, radius)
            preds[s] = ops.to_dense(rows)
            coarser = (preds[s], rows[:ops.torus])
        preds[0] = self.add_prior(preds[0], grids[0])
        return preds


def _occupancy(g: torch.Tensor) -> torch.Tensor:
    """(B, X, Y, Z) float occupancy from (B, X, Y, Z) or (B, 1, X, Y, Z), bool or float."""
    if g.dim() == 5 and g.shape[1] == 1:
        g = g[:, 0]
    if g.dim() != 4:
        raise ModelError(f"occupancy must be (B, X, Y, Z) or (B, 1, X, Y, Z), got {tuple(g.shape)}")
    return g.to(torch.float32)
