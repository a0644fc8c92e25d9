"""Training loss (paper eq. 25-27): vertex MSE on surface cells + lambda * edge BCE.

    L = L_V + lambda L_E

* L_V: squared distance between predicted and true dual vertex (offsets, summed over x, y, z),
  averaged over the surface cells only; other cells have no vertex (UNDC masks them too).
* L_E: binary cross-entropy with logits of the 3 edge channels, averaged over all points.
  (The paper's text says BCE; its eq. 27 prints a squared error, we follow the text.)
* lambda is learnable. Minimising ``L_V + lambda L_E`` over lambda directly would drive it to 0,
  so we use homoscedastic uncertainty weighting (Kendall, Gal & Cipolla, CVPR 2018):
  ``lambda = exp(-t)`` and the loss gets ``+ t``. At the optimum lambda = 1 / L_E: the edge term
  is rescaled to ~1 as it shrinks, and lambda can neither reach 0 (the ``+ t`` grows without
  bound) nor go negative.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn

from ..errors import ModelError


def vertex_edge_losses(pred: torch.Tensor, vertex: torch.Tensor, edge: torch.Tensor,
                       surface: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """(L_V, L_E) of one scale.

    Args:
        pred: (B, 6, X, Y, Z) network output P_s (vertex offsets, edge logits).
        vertex: (B, X, Y, Z, 3) float true vertex offsets (labels.ScaleLabels.vertex layout).
        edge: (B, X, Y, Z, 3) bool/float true edge flags.
        surface: (B, X, Y, Z) bool, cells that have a vertex.

    Returns:
        two scalar tensors.
    """
    b, c, *dims = pred.shape
    want = (b, *dims)
    if c != 6 or tuple(vertex.shape) != (*want, 3) or tuple(edge.shape) != (*want, 3) \
            or tuple(surface.shape) != want:
        raise ModelError(f"loss: prediction {tuple(pred.shape)} needs vertex/edge (B, X, Y, Z, 3) "
                         f"and surface (B, X, Y, Z) of {want}; got {tuple(vertex.shape)}, "
                         f"{tuple(edge.shape)}, {tuple(surface.shape)}")
    # (B, X, Y, Z, 6)
    pred = pred.permute(0, 2, 3, 4, 1)
    mask = surface.to(pred.dtype)
    squared = ((pred[..., :3] - vertex.to(pred.dtype)) ** 2).sum(-1)
    loss_v = (squared * mask).sum() / mask.sum().clamp_min(1.0)
    loss_e = F.binary_cross_entropy_with_logits(pred[..., 3:], edge.to(pred.dtype))
    return loss_v, loss_e


class AGNDCLoss(nn.Module):
    """``L_V + exp(-t) L_E + t`` with learnable ``t`` (module docstring)."""

    def __init__(self, init_lambda: float = 1.0):
        super().__init__()
        if not init_lambda > 0:
            raise ModelError(f"init_lambda must be > 0, got {init_lambda}")
        self.t = nn.Parameter(torch.tensor(-math.log(init_lambda)))

    @property
    def weight(self) -> torch.Tensor:
        """Current lambda = exp(-t)."""
        return torch.exp(-self.t)

    def forward(self, pred, vertex, edge, surface) -> tuple[torch.Tensor, dict]:
        """Total loss and its parts ({"vertex", "edge", "lambda"}, detached floats)."""
        loss_v, loss_e = vertex_edge_losses(pred, vertex, edge, surface)
        total = loss_v + self.weight * loss_e + self.t
        parts = {"vertex": float(loss_v.detach()), "edge": float(loss_e.detach()),
                 "lambda": float(self.weight.detach())}
        return total, parts
