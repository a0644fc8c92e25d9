"""Constrained elastic surface nets (Gibson 1998) against plain surface nets, on a mesh folder.

    .venv/bin/python research/elastic_nets.py DATA [--res 64] [--passes 1,2,4,16,64] -o ROWS.csv

Each mesh's grid (centred, grid alone) is remeshed by marching cubes and surface nets; then the
surface nets vertices are relaxed: every pass moves each vertex a share ``--step`` of the way to
the mean of its mesh neighbours and clamps it into its own cell (the cube of lattice points the
surface crosses there, so the mesh stays consistent with the grid). ``--step 1`` is Gibson's
relaxation, the smoothing that medical tools apply to surface nets. Printed: the mean CD×10⁵ and
NC of each variant by class (the folder's ``MANIFEST.csv`` kinds), and on how many meshes each
is closer than plain surface nets. docs/experiments/classical-context.md has the measurements.
"""

from __future__ import annotations

import argparse
import csv
from collections import defaultdict
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from agndc_core.grid import LATTICE_PAD, lattice_to_world
from agndc_core.gridio import load_mesh
from agndc_core.metrics import evaluate
from agndc_core.pipeline import remesh
from agndc_core.voxelize import voxelize


def relax(vertices_vx3: np.ndarray, faces_fx3: np.ndarray, cells_vx3: np.ndarray, passes: int,
          step: float) -> np.ndarray:
    """``passes`` of Laplacian relaxation, each vertex clamped into its cell [c, c + 1]³."""
    i = faces_fx3[:, [0, 1, 2, 1, 2, 0]].ravel()
    j = faces_fx3[:, [1, 2, 0, 0, 1, 2]].ravel()
    n = len(vertices_vx3)
    neighbours = sp.coo_matrix((np.ones(len(i)), (i, j)), shape=(n, n)).tocsr()
    neighbours.data[:] = 1.0  # an edge shared by two faces counts once
    degree = np.maximum(np.asarray(neighbours.sum(axis=1)).ravel(), 1.0)[:, None]
    out = vertices_vx3.copy()
    for _ in range(passes):
        mean = neighbours @ out / degree
        out = np.clip(out + step * (mean - out), cells_vx3, cells_vx3 + 1.0)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", type=Path, help="meshes with a MANIFEST.csv (agndc val-data)")
    parser.add_argument("-o", "--out", type=Path, required=True, help="rows (CSV)")
    parser.add_argument("--res", type=int, default=64)
    parser.add_argument("--passes", default="1,2,4,16,64")
    parser.add_argument("--step", type=float, default=0.5)
    parser.add_argument("--samples", type=int, default=30000)
    args = parser.parse_args()
    passes = [int(p) for p in args.passes.split(",")]
    manifest = list(csv.DictReader(open(args.folder / "MANIFEST.csv")))
    rows = []
    for entry in manifest:
        vertices, faces = load_mesh(args.folder / entry["file"])
        grid = voxelize(vertices, faces, args.res)
        # grid alone: not the voxelised mesh's bounding box, which the grid does not hold
        nets = remesh(grid, method="surfacenets", reframe=False, source_bounds=False)
        lattice = grid.world_to_index(nets.vertices) + LATTICE_PAD  # lattice_to_world inverted
        # surface nets vertices lie inside their cells (a face's offset can be exactly 0)
        cells = np.floor(lattice + 1e-6)
        marching = remesh(grid, method="mc", reframe=False, source_bounds=False)
        candidates = {"mc": (marching.vertices, marching.faces),
                      "surfacenets": (nets.vertices, nets.faces)}
        for k in passes:
            relaxed = relax(lattice, nets.faces, cells, k, args.step)
            candidates[f"elastic{k}"] = (lattice_to_world(relaxed, grid.affine), nets.faces)
        for method, (v, f) in candidates.items():
            m = evaluate(v, f, vertices, faces, n_samples=args.samples)
            rows.append({"name": Path(entry["file"]).stem, "kind": entry["kind"],
                         "method": method, "cd": m["cd"], "nc": m["nc"]})
    with open(args.out, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    nets_cd = {r["name"]: r["cd"] for r in rows if r["method"] == "surfacenets"}
    table = defaultdict(lambda: defaultdict(list))
    for r in rows:
        for key in ("all", r["kind"]):
            table[r["method"]][key].append((r["cd"], r["nc"]))
    for method, groups in table.items():
        parts = [f"{key} CD {np.mean([c for c, _ in v]) * 1e5:.3f} "
                 f"NC {np.mean([n for _, n in v]):.3f}" for key, v in sorted(groups.items())]
        closer = sum(r["cd"] < nets_cd[r["name"]] for r in rows if r["method"] == method)
        print(f"{method:12s} " + " | ".join(parts) + f" | closer than surface nets: {closer}")


if __name__ == "__main__":
    main()
