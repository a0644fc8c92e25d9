"""Distilled training data: a teacher network's finest vertices as the labels a student learns.

The cascade the CPU runtime ships is too slow for some targets (docs/experiments/student.md); a
cheaper student (narrower, plain convolutions, a smaller band) has to reproduce what the teacher
does, not only approach the true surface. ``distil_dataset`` copies a folder of ``agndc
train-data`` samples, replacing the finest scale's vertex labels on its surface cells by

    vertex0 = (1 - w) * true vertex + w * teacher vertex,

where the teacher ran on the sample's whole lattice exactly as ``remesh`` runs it (numpy runtime,
band inference, the trained framing). The teacher's vertex is defined on every surface cell and
is a target a binary neighbourhood can reach; the true depth of a flat face often is not
(docs/experiments/binary-targets-curriculum.md). Coarser scales keep their true labels (they
cost little at inference, and the student's coarse scales learn them as the teacher's did).
Everything else of a sample (quadrics, edges, the mesh for validation) is copied unchanged, so a
distilled folder trains with plain ``agndc train --data``; keep the validation samples true.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import AGNDCError


def distil_sample(network, sample: dict, weight: float = 1.0) -> dict:
    """One sample (the arrays of ``data.load_sample``, ``recipe`` as stored) with ``vertex0``
    mixed towards ``network``'s prediction on its surface cells (module docstring)."""
    from ..inference import predict_lattice

    if not 0.0 <= weight <= 1.0:
        raise AGNDCError(f"teacher weight must be in [0, 1], got {weight}")
    teacher, _ = predict_lattice(network, sample["lattice"], edges=False)  # (X, Y, Z, 3)
    true = sample["vertex0"]
    mixed = (1.0 - weight) * true + weight * teacher
    out = dict(sample)
    out["vertex0"] = np.where(sample["surface0"][..., None], mixed, true).astype(np.float32)
    return out


def distil_dataset(source, out, teacher, weight: float = 1.0, threads: int = 1,
                   progress: bool = True) -> list[Path]:
    """Write every ``sample_*.npz`` of ``source`` into ``out`` with its finest vertex labels
    distilled from the ``teacher`` checkpoint; samples already in ``out`` are kept (resumable).

    Returns:
        the paths of the distilled samples, in name order.
    """
    from tqdm import tqdm

    from ..pipeline import load_model, set_inference_threads

    paths = sorted(Path(source).glob("sample_*.npz"))
    if not paths:
        raise AGNDCError(f"no training samples (sample_*.npz) in {source}")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    set_inference_threads(threads)
    network = load_model(teacher)
    written = []
    for path in tqdm(paths, desc="distil", disable=not progress):
        target = out / path.name
        if not target.exists():
            with np.load(path) as data:
                sample = {key: data[key] for key in data.files}
            part = target.with_name(target.name + ".part")
            with open(part, "wb") as f:  # written aside and renamed, as build_dataset does
                np.savez_compressed(f, **distil_sample(network, sample, weight))
            part.replace(target)
        written.append(target)
    return written
