"""Training loss (paper eq. 25-27): vertex MSE on surface cells + lambda * edge BCE.

    L = L_V + lambda L_E

* L_V: squared distance between predicted and true dual vertex (offsets, summed over x, y, z),
  averaged over the surface cells only; other cells have no vertex (UNDC masks them too).
  With the cells' normal quadrics Q (``labels.ScaleLabels.quadric``) the distance is measured
  as d^T (Q + QUADRIC_FLOOR I) d: mostly across the true surface, where an error moves the
  mesh, and little along it, where the target is only the centroid of the cell's patch, a
  position binary input barely determines (on the dev parts it is ~2/3 of the plain MSE of
  surface nets).
  With ``crease_weight`` c > 0 the mean is weighted: a cell counts 1 + c min(1, I2 / CREASE_I2),
  I2 the sum of Q's principal 2x2 minors (p (1 - p) sin^2 theta for two faces at angle theta with
  area shares p, 0 on a flat face, ~1e-3 on a smooth surface at 64^3). Crease and corner cells
  are ~5 % of a part's surface cells, and they are where the edge metrics (ECD, EF1) are decided.
* L_E: binary cross-entropy with logits of the 3 edge channels, averaged over the valid points
  (all of them unless a ``valid`` mask says which points have their whole receptive field in
  real data). Where the edges come from the input (the finest scale with input topology) there
  is nothing to learn: ``AGNDCLoss(train_edges=False)`` leaves L_E out (it is still reported).
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

#: weight of the isotropic part of the quadric-weighted vertex loss: keeps vertices from sliding
#: along flat faces, small enough that the error across the surface dominates
QUADRIC_FLOOR = 0.1
#: the second quadric invariant I2 at which a cell counts as a full crease (faces ~40 degrees
#: apart at equal areas; 0.25 for a right angle)
CREASE_I2 = 0.1


def vertex_edge_losses(pred: torch.Tensor, vertex: torch.Tensor, edge: torch.Tensor,
                       surface: torch.Tensor, valid: torch.Tensor | None = None,
                       quadric: torch.Tensor | None = None,
                       quadric_floor: float = QUADRIC_FLOOR,
                       crease_weight: float = 0.0
                       ) -> tuple[torch.Tensor, torch.Tensor]:
    """(L_V, L_E) of one scale.

    Args:
        pred: (B, 6, X, Y, Z) network output P_s (vertex offsets, edge logits).
        vertex: (B, X, Y, Z, 3) float true vertex offsets (labels.ScaleLabels.vertex layout).
        edge: (B, X, Y, Z, 3) bool/float true edge flags.
        surface: (B, X, Y, Z) bool, cells that have a vertex (and are valid).
        valid: optional (B, X, Y, Z) bool, points whose edges are scored (default: all).
        quadric: optional (B, X, Y, Z, 6) float normal quadrics (xx, yy, zz, xy, yz, zx).
        quadric_floor: weight of the plain squared distance added to the quadric term.
        crease_weight: extra weight c of the crease cells in the vertex mean (module docstring;
            needs ``quadric``).

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
    mask = surface.float()
    d = pred[..., :3].float() - vertex.float()
    if quadric is None:
        squared = (d**2).sum(-1)
    else:
        q = quadric.float()
        squared = (q[..., 0] * d[..., 0] ** 2 + q[..., 1] * d[..., 1] ** 2
                   + q[..., 2] * d[..., 2] ** 2 + 2 * (q[..., 3] * d[..., 0] * d[..., 1]
                                                      + q[..., 4] * d[..., 1] * d[..., 2]
                                                      + q[..., 5] * d[..., 2] * d[..., 0]))
        squared = squared + quadric_floor * (d**2).sum(-1)
        if crease_weight > 0:
            minors = (q[..., 0] * q[..., 1] - q[..., 3] ** 2 + q[..., 1] * q[..., 2]
                      - q[..., 4] ** 2 + q[..., 2] * q[..., 0] - q[..., 5] ** 2)
            mask = mask * (1.0 + crease_weight * (minors / CREASE_I2).clamp(0.0, 1.0))
    loss_v = (squared * mask).sum() / mask.sum().clamp_min(1.0)
    bce = F.binary_cross_entropy_with_logits(pred[..., 3:].float(), edge.float(), reduction="none")
    if valid is None:
        loss_e = bce.mean()
    else:
        weight = valid.to(bce.dtype)[..., None].expand_as(bce)
        loss_e = (bce * weight).sum() / weight.sum().clamp_min(1.0)
    return loss_v, loss_e


class AGNDCLoss(nn.Module):
    """``L_V + exp(-t) L_E + t`` with learnable ``t`` (module docstring)."""

    def __init__(self, init_lambda: float = 1.0, train_edges: bool = True,
                 quadric_floor: float = QUADRIC_FLOOR, crease_weight: float = 0.0):
        super().__init__()
        self.train_edges = train_edges
        if not quadric_floor >= 0:
            raise ModelError(f"quadric_floor must be >= 0, got {quadric_floor}")
        if not crease_weight >= 0:
            raise ModelError(f"crease_weight must be >= 0, got {crease_weight}")
        self.quadric_floor = float(quadric_floor)
        self.crease_weight = float(crease_weight)
        if not init_lambda > 0:
            raise ModelError(f"init_lambda must be > 0, got {init_lambda}")
        self.t = nn.Parameter(torch.tensor(-math.log(init_lambda)))

    @property
    def weight(self) -> torch.Tensor:
        """Current lambda = exp(-t)."""
        return torch.exp(-self.t)

    def forward(self, pred, vertex, edge, surface, valid=None, quadric=None
                ) -> tuple[torch.Tensor, dict]:
        """Total loss and its parts ({"vertex", "edge", "lambda"}, detached floats)."""
        total, parts = self.terms(pred, vertex, edge, surface, valid, quadric)
        return total, {k: float(v) for k, v in parts.items()}

    def terms(self, pred, vertex, edge, surface, valid=None, quadric=None
              ) -> tuple[torch.Tensor, dict]:
        """``forward`` with the parts as detached 0-d tensors: no host sync, so a training
        step can run ahead of the GPU (and be traced whole by torch.compile)."""
        loss_v, loss_e = vertex_edge_losses(pred, vertex, edge, surface, valid, quadric,
                                            self.quadric_floor, self.crease_weight)
        parts = {"vertex": loss_v.detach(), "edge": loss_e.detach(),
                 "lambda": self.weight.detach() if self.train_edges
                 else torch.zeros((), device=pred.device)}
        if not self.train_edges:
            return loss_v, parts
        total = loss_v + self.weight * loss_e + self.t
        return total, parts
