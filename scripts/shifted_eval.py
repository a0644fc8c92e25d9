"""Grid-alone evaluation of the dev meshes voxelised with a random sub-voxel shift.

    .venv/bin/python scripts/shifted_eval.py [--res 64] [--out rows.csv]
        [--method LABEL=METHOD[:CHECKPOINT] ...]

``agndc eval`` voxelises every mesh with ``voxelize``'s centring, which puts the faces of the
bounding box at fixed places in their voxel layers (docs/training.md, session of 2026-11-25,
seventh). Here each mesh is voxelised with a shift drawn uniformly from [-0.5, 0.5) voxel per
axis (seeded by the mesh's index, so every method sees the same grid), as the training data
are, and the methods see that grid alone. Prints the means over the meshes as ``agndc eval``'s
markdown table.
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

import numpy as np

from agndc_core.evaluate import METRIC_COLUMNS, markdown_table, require_meshes, summarize_rows
from agndc_core.gridio import load_mesh
from agndc_core.labels import make_labels
from agndc_core.metrics import evaluate
from agndc_core.pipeline import remesh
from agndc_core.voxelize import voxelize

DEFAULT_METHODS = ("mc=mc", "surfacenets=surfacenets", "oracle_binary=oracle_binary",
                   "undc=undc", "agndc=agndc")


def parse_method(text: str) -> tuple[str, str, str | None]:
    label, _, spec = text.partition("=")
    method, _, checkpoint = spec.partition(":")
    return label, method or label, checkpoint or None


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dev", default="../shared/data/dev")
    parser.add_argument("--res", type=int, default=64)
    parser.add_argument("--out", type=Path, default=Path("out/shifted_rows.csv"))
    parser.add_argument("--method", action="append", default=[],
                        metavar="LABEL=METHOD[:CHECKPOINT]")
    args = parser.parse_args()
    methods = [parse_method(m) for m in (args.method or DEFAULT_METHODS)]
    rows = []
    for index, (path, kind) in enumerate(require_meshes(args.dev)):
        vertices, faces = load_mesh(path)
        shift = np.random.default_rng([index, 77]).uniform(-0.5, 0.5, 3)
        grid = voxelize(vertices, faces, args.res, shift=shift, source=Path(path).name)
        labels = make_labels(vertices, faces, grid, levels=0)  # for the oracles
        for label, method, checkpoint in methods:
            result = remesh(grid, method=method, checkpoint=checkpoint, labels=labels,
                            reframe=False, source_bounds=False, threads=2)
            metrics = evaluate(result.vertices, result.faces, vertices, faces)
            rows.append({"name": Path(path).stem, "category": kind, "method": label,
                         **{k: metrics[k] for k in METRIC_COLUMNS}, "seconds": result.seconds})
        print(Path(path).stem, flush=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    with open(args.out, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    print(markdown_table(summarize_rows(rows)))


if __name__ == "__main__":
    main()
