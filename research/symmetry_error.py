"""How far a network is from the grid's symmetries (``agndc_core.study.symmetry``), beside surface
nets.

    .venv/bin/python research/symmetry_error.py [--checkpoint PATH ...] [--mesh FILE] [--res 64]

Voxelises ``--mesh`` (default: a 1 x 0.8 x 0.6 box, whose right vertices on the faces are the
surface nets ones) at ``--res`` and prints, for surface nets and each checkpoint (default: the
shipped AGNDC), the RMS change of the vertices in voxels when the grid is mirrored along each axis
or shifted along x, and the RMS distance of the network's vertices from surface nets' (how much
the network moves them at all). Surface nets is exact: its row is all zeros.

With the default box, it also prints ``face_phase_offsets``: where each predictor puts the box's
two faces normal to each axis (mean offset along +axis from surface nets, voxels) as the box is
shifted through the 4 phases of the cascade's pooling grid.
"""

import argparse

import numpy as np
import torch
import trimesh

from agndc_core.checkpoint import default_checkpoint_path
from agndc_core.grid import pad_to_lattice
from agndc_core.inference import predict_lattice
from agndc_core.labels import crossed_edges, surface_cells
from agndc_core.pipeline import load_model
from agndc_core.study.symmetry import face_phase_offsets, symmetry_errors
from agndc_core.surfacenets import surface_nets_lattice
from agndc_core.voxelize import voxelize


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--checkpoint", action="append", default=[])
    parser.add_argument("--mesh", help="mesh file (default: a box)")
    parser.add_argument("--res", type=int, default=64)
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    mesh = (trimesh.load(args.mesh, force="mesh") if args.mesh
            else trimesh.creation.box(extents=(1.0, 0.8, 0.6)))
    lattice = pad_to_lattice(voxelize(mesh.vertices, mesh.faces, args.res).occupancy)
    cells = surface_cells(crossed_edges(lattice))
    reference = surface_nets_lattice(lattice)
    predictors = {"surfacenets": surface_nets_lattice}
    for path in args.checkpoint or [str(default_checkpoint_path("agndc"))]:
        model = load_model(path)
        # the raw network (canonical=False): the pipeline re-frames shifted grids, which would
        # hide it
        predictors[path] = lambda lat, model=model: predict_lattice(model, lat, canonical=False)[0]
    print(f"{args.mesh or 'box 1 x 0.8 x 0.6'} at {args.res}, {cells.sum()} surface cells; "
          "RMS vertex change in voxels")
    for name, predict in predictors.items():
        errors = symmetry_errors(predict, lattice)
        moved = np.sqrt(np.mean(np.sum((predict(lattice) - reference)[cells] ** 2, axis=-1)))
        print(f"{name}\n  " + "  ".join(f"{k} {v:.3f}" for k, v in errors.items())
              + f"  | moved from surface nets {moved:.3f}")
        if args.mesh:
            continue
        for axis in range(3):
            offsets = face_phase_offsets(predict, lattice, axis)
            print(f"  {'xyz'[axis]} faces (low, high) at shift 0..3: "
                  + "  ".join(f"({lo:+.3f}, {hi:+.3f})" for lo, hi in offsets))


if __name__ == "__main__":
    main()
