"""The torch side of ``inference.predict_lattice``: the context a torch network runs in, and the
dense reference forward. Imported only for torch models, so the inference module itself (and the
extension, which runs the numpy runtime) never imports torch."""

from __future__ import annotations

from contextlib import ExitStack

import torch
from torch.overrides import TorchFunctionMode


class Watch(TorchFunctionMode):
    """While active (on this thread only), every torch call first calls ``tick``: progress and
    cancellation from inside the network (``inference._Reporter.tick``)."""

    def __init__(self, tick):
        super().__init__()
        self.tick = tick

    def __torch_function__(self, func, types, args=(), kwargs=None):
        self.tick()
        return func(*args, **(kwargs or {}))


def running(report) -> ExitStack:
    """Inference mode, plus the watch when the reporter has a progress or cancel callback."""
    stack = ExitStack()
    stack.enter_context(torch.inference_mode())
    if report.active:
        stack.enter_context(Watch(report.tick))
    return stack


def predict_dense(model, padded, report) -> torch.Tensor:
    """(X, Y, Z, 6) prediction of the plain training forward on the whole lattice (reference;
    slow on a CPU)."""
    report(0.0, "network (dense)")
    with running(report):
        g = torch.from_numpy(padded)[None].to(next(model.parameters()).device)
        return model(g)[0][0].permute(1, 2, 3, 0)
