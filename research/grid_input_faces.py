"""Grids that did not come from a mesh: the outermost flat faces at the network's mean or mid-layer.

    .venv/bin/python research/grid_input_faces.py VAL/family -o OUT [--res 64] [--samples 30000]

The flat-patch stage gives the patches of a shape's outermost layer along an axis the mean of the
network's depths there (``flatpatches.mean_depth_layers``): a voxelised mesh's bounding faces lie
where the voxeliser's frame puts them, and the network has learned that frame. A grid that comes
as a grid (a voxel model, a segmentation mask, an array) has no such frame. This study remeshes
the validation family's shapes as grids (``pipeline.remesh``, the grid input path, no source
bounds) in two frames, each with the rule as shipped and with every flat patch mid-layer:

* ``voxel``: a voxel model. The grid of each mesh at ``--res`` (centred), and the truth is the
  grid's own voxel surface (``report.voxel_faces``), whose flat faces all lie mid-layer;
* ``mask``: a segmentation mask. The grid of each mesh at ``--res`` moved by a random sub-voxel
  shift (seeded per shape), so where a face lies in its layer is unknown, and the truth is the
  mesh.

Rows (``OUT/FRAME/rows.csv``, the columns of ``agndc eval``; methods ``mc``, ``agndc`` and
``agndc_mid``) and each frame's means are written; compare them with
``research/compare_rows.py OUT/FRAME/rows.csv ...`` or read the printed means.
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path
from unittest import mock

import numpy as np


def all_mid_layer(lattice: np.ndarray, axis: int):
    """``mean_depth_layers`` with no layer taking the mean: every flat patch mid-layer."""
    from agndc_core.flatpatches import KINDS

    layers = lattice.shape[axis] - 1
    return {kind: np.zeros(layers, dtype=bool) for kind in KINDS}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("folder")
    parser.add_argument("-o", "--out", required=True)
    parser.add_argument("--res", type=int, default=64)
    parser.add_argument("--samples", type=int, default=30000)
    parser.add_argument("--frames", default="voxel,mask")
    args = parser.parse_args()

    from agndc_core import flatpatches
    from agndc_core.grid import VoxelGrid
    from agndc_core.gridio import load_mesh
    from agndc_core.metrics import evaluate
    from agndc_core.pipeline import remesh
    from agndc_core.study.evaluate import METRIC_COLUMNS, find_meshes, summarize_rows
    from agndc_core.study.report import voxel_faces
    from agndc_core.voxelize import voxelize

    meshes = find_meshes(Path(args.folder))
    for frame in args.frames.split(","):
        rows = []
        for index, (path, kind) in enumerate(meshes):
            vertices, faces = load_mesh(path)
            shift = (0.0, 0.0, 0.0)
            if frame == "mask":
                shift = tuple(np.random.default_rng(index).uniform(-0.5, 0.5, 3))
            voxelised = voxelize(vertices, faces, args.res, shift=shift)
            grid = VoxelGrid(voxelised.occupancy, voxelised.affine, source=Path(path).name)
            truth = voxel_faces(grid) if frame == "voxel" else (vertices, faces)
            for label in ("mc", "agndc", "agndc_mid"):
                method = "mc" if label == "mc" else "agndc"
                if label == "agndc_mid":
                    with mock.patch.object(flatpatches, "mean_depth_layers", all_mid_layer):
                        result = remesh(grid, method=method)
                else:
                    result = remesh(grid, method=method)
                metrics = evaluate(result.vertices, result.faces, *truth,
                                   n_samples=args.samples)
                row = {"mesh": str(path), "name": Path(path).stem, "category": kind,
                       "method": label, "resolution": args.res, "shift": ""}
                row.update({c: metrics[c] for c in METRIC_COLUMNS})
                row.update(faces=len(result.faces), seconds=result.seconds)
                rows.append(row)
            print(frame, Path(path).stem, " ".join(f"{r['method']} {1e5 * r['cd']:.3f}"
                                                   for r in rows[-3:]), flush=True)
        dest = Path(args.out) / frame
        dest.mkdir(parents=True, exist_ok=True)
        with open(dest / "rows.csv", "w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=list(rows[0]))
            writer.writeheader()
            writer.writerows(rows)
        for summary in summarize_rows(rows):
            cd = np.array([r["cd"] for r in rows if r["method"] == summary["method"]])
            print(f"{frame} {summary['method']:10s} CD {1e5 * summary['cd']:.3f} NC "
                  f"{summary['nc']:.4f} ECD {1e2 * summary['ecd']:.2f} EF1 {summary['ef1']:.3f} "
                  f"({len(cd)} shapes)")
        mean = {r["name"]: r["cd"] for r in rows if r["method"] == "agndc"}
        mid = {r["name"]: r["cd"] for r in rows if r["method"] == "agndc_mid"}
        print(f"{frame}: mid-layer better on {sum(mid[n] < mean[n] for n in mean)}, worse on "
              f"{sum(mid[n] > mean[n] for n in mean)} of {len(mean)}")


if __name__ == "__main__":
    main()
