"""How low can a binary-input method's CD go? The ground truth substituted into a network's
vertices, one class of cells at a time.

    python research/headroom_bound.py [DEV_FOLDER] [--res 64] [--shifts 0] [--checkpoint PATH]
        [--alphas 0.75 0.5 0.25] [--limit N] [--generated N]

Each mesh is voxelised as ``agndc eval`` does (the centred grid, or ``--shifts K`` grids); the
network (``--checkpoint``, default the shipped AGNDC) predicts its vertices, and each variant
below is dual-contoured on the grid's own edges with no flat-patch stage and no normal filter
(the filter moves exact vertices off the surface). CD is measured as ``agndc eval`` measures it.

* ``mc`` and ``oracle`` (ground-truth labels): the ends of the headroom;
* ``network``: the network's vertices as contoured;
* ``oracle_binary``: the ground truth, with surface nets' midpoint along the normal on exactly
  axis-aligned faces (``labels.binary_visible_vertex``);
* ``network_depth``: the ground truth, with the **network's** coordinate along the normal on
  exactly axis-aligned faces. It is what a method would score if it were exact on every cell
  whose surface is not axis-aligned (68 % of the surface cells of the dev meshes at 64³), an
  optimistic bound: there the oracle uses the mesh's exact intersections, which the grid does not
  hold;
* ``true_depth``: the converse, the network's vertices with the ground truth's coordinate along
  the normal on exactly axis-aligned faces (a depth the grid does not hold): what the network
  loses on every other cell;
* ``network_depth_a``: the same with the network's axis-aligned depth error scaled by ``a``
  (``--alphas``): how much better than the network those depths would have to be.

Prints one JSON line per grid, then the means and each variant's share of the MC→oracle CD
headroom (docs/experiments/headroom-bound.md).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import torch

from agndc_core.checkpoint import default_checkpoint_path, load_checkpoint
from agndc_core.contour import dual_contour
from agndc_core.grid import lattice_to_world, pad_to_lattice
from agndc_core.gridio import load_mesh
from agndc_core.inference import predict_lattice
from agndc_core.labels import binary_visible_vertex, crossed_edges, make_labels
from agndc_core.metrics import evaluate
from agndc_core.pipeline import orient_to_affine, remesh
from agndc_core.study.evaluate import grid_placements, require_meshes
from agndc_core.study.shapes import generate_shape, shape_family
from agndc_core.surfacenets import surface_nets_lattice
from agndc_core.voxelize import voxelize

CD_SCALE = 1e5  # CD×10⁵, as the reports print it
#: first seed of ``--generated``: outside the training (0..) and validation (1,000,000..) ranges,
#: as the shipped-weights test's held-out parts
HELD_OUT_SEED0 = 7_000_001


def variants(labels, network: np.ndarray, lattice: np.ndarray, alphas) -> dict:
    """{name: (X, Y, Z, 3) vertex offsets} of every substitution of the module docstring."""
    truth = labels.vertex
    out = {"network": network,
           "oracle_binary": binary_visible_vertex(truth, labels.quadric,
                                                  surface_nets_lattice(lattice)),
           "network_depth": binary_visible_vertex(truth, labels.quadric, network),
           "true_depth": binary_visible_vertex(network, labels.quadric, truth),
           "oracle": truth}
    for a in alphas:
        scaled = truth + a * (network - truth)
        out[f"network_depth_{a:g}"] = binary_visible_vertex(truth, labels.quadric, scaled)
    return out


def score_grid(vertices, faces, grid, model, alphas, n_samples: int) -> dict:
    """CD×10⁵ of every variant (and of marching cubes) on one voxelised grid."""
    lattice = pad_to_lattice(grid.occupancy)
    labels = make_labels(vertices, faces, grid, levels=0)[0]
    with torch.inference_mode():
        network, _ = predict_lattice(model, lattice, canonical=False)
    edge = crossed_edges(lattice)
    mc = remesh(grid, method="mc")  # the same grid: voxelised once
    scores = {"mc": CD_SCALE * evaluate(mc.vertices, mc.faces, vertices, faces,
                                        n_samples=n_samples)["cd"]}
    for name, vertex in variants(labels, np.asarray(network, np.float32), lattice,
                                 alphas).items():
        v, f = dual_contour(vertex, edge, lattice)
        world = lattice_to_world(v, grid.affine)
        scores[name] = CD_SCALE * evaluate(world, orient_to_affine(f, grid.affine), vertices,
                                           faces, n_samples=n_samples)["cd"]
    return scores


def shapes(args):
    """Yield (name, category, (V, 3) vertices, (F, 3) faces): the dev meshes, or ``--generated``
    held-out shapes of the training data's generator (category: the shape family)."""
    if args.generated:
        for seed in range(HELD_OUT_SEED0, HELD_OUT_SEED0 + args.generated):
            yield f"seed{seed}", shape_family(seed), *generate_shape(seed)
        return
    for path, kind in require_meshes(Path(args.dev), args.limit):
        yield (path.stem, kind, *load_mesh(path))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("dev", nargs="?", default="../shared/data/dev")
    parser.add_argument("--res", type=int, default=64)
    parser.add_argument("--shifts", type=int, default=0)
    parser.add_argument("--checkpoint", default=str(default_checkpoint_path("agndc")))
    parser.add_argument("--alphas", type=float, nargs="*", default=[0.75, 0.5, 0.25])
    parser.add_argument("--limit", type=int, default=None)
    parser.add_argument("--generated", type=int, default=0, metavar="N",
                        help="score N held-out generated shapes (seeds from 7,000,001, outside "
                             "the training and validation ranges) instead of DEV_FOLDER")
    parser.add_argument("--samples", type=int, default=100_000)
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    model, _ = load_checkpoint(args.checkpoint)
    rows = []
    for index, (name, kind, vertices, faces) in enumerate(shapes(args)):
        for k, shift in grid_placements(index, args.shifts):
            grid = voxelize(vertices, faces, args.res, shift=tuple(shift), source=name)
            row = {"name": name, "category": kind, "shift": k}
            row.update(score_grid(vertices, faces, grid, model, args.alphas, args.samples))
            rows.append(row)
            print(json.dumps(row), flush=True)
    names = [k for k in rows[0] if k not in ("name", "category", "shift")]
    mean = {k: float(np.mean([r[k] for r in rows])) for k in names}
    span = mean["mc"] - mean["oracle"]
    print(f"\nmeans over {len(rows)} grids at {args.res}³ (CD×10⁵, share of the MC→oracle "
          "headroom):")
    for k in names:
        print(f"  {k:22s} {mean[k]:7.3f}  {100 * (mean['mc'] - mean[k]) / span:6.1f} %")


if __name__ == "__main__":
    main()
