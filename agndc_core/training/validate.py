"""Validation on held-out synthetic samples: CD/F1/NC/ECD/EF1 of the model and of marching cubes.

Each sample is reconstructed the way users get it (``inference.predict_lattice`` band path, input
topology, ``contour.dual_contour``) and scored against the generator's exact mesh.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..contour import dual_contour
from ..grid import crossed_edges, lattice_to_world
from ..mc import marching_cubes_lattice
from ..metrics import evaluate, format_row
from .data import load_sample, sample_mesh

KEYS = ("cd", "f1", "nc", "ecd", "ef1")


def reconstruct_sample(model, sample: dict, mode: str = "band") -> tuple[np.ndarray, np.ndarray]:
    """World-space mesh of one sample's lattice by the model (input topology)."""
    from ..inference import predict_lattice

    lattice = sample["lattice"]
    vertex, _ = predict_lattice(model, lattice, mode=mode)
    vertices, faces = dual_contour(vertex, crossed_edges(lattice), lattice)
    return lattice_to_world(vertices, sample["affine"]), faces


def validate_model(model, folder, *, count: int = 8, n_samples: int = 20_000,
                   mode: str = "band") -> dict:
    """Mean paper-unit metrics of the model and of marching cubes on ``count`` samples."""
    paths = sorted(Path(folder).glob("sample_*.npz"))[:count]
    rows = {"model": [], "mc": []}
    for path in paths:
        sample = load_sample(path)
        gt_v, gt_f = sample_mesh(sample)
        v, f = reconstruct_sample(model, sample, mode)
        rows["model"].append(format_row(evaluate(v, f, gt_v, gt_f, n_samples=n_samples)))
        mc_v, mc_f = marching_cubes_lattice(sample["lattice"])
        mc_world = lattice_to_world(mc_v, sample["affine"])
        rows["mc"].append(format_row(evaluate(mc_world, mc_f, gt_v, gt_f, n_samples=n_samples)))
    return {"val_samples": len(paths), "n_surface_samples": n_samples,
            **{name: {k: float(np.nanmean([r[k] for r in rs])) for k in KEYS}
               for name, rs in rows.items()}}
