"""``agndc eval`` with the terraces that the network itself calls flat flattened too.

``flatpatches.flatten_patches`` leaves a flat patch to the network when a pure split of the same
kind lies one layer up or down within ``tol.terrace_reach`` cells (a *terrace*: the surface may
step through the layers there, as a slanted or curved one does), and ``fit_terraced_planes``
fits the terraces of slightly tilted planes. A flat face one voxel below another (a recessed
floor, a one-voxel step, a shallow pocket) is a terrace by that test and keeps the network's
depth, which for faces inside the shape's extent is biased (docs/experiments/flat-patches.md).
This study flattens, after the terraced-plane fit, every terrace patch that no plane took,
of at least ``--min-cells`` cells, whose network coordinates along the axis have a standard
deviation of at most ``--max-std`` voxels (the network sees no slope or curvature across it):
at the layer's midpoint inside the shape's extent, at the patch's mean on its outermost layers,
as ``flatten_patches`` does for the patches it flattens.

    .venv/bin/python research/flat_terraces.py DATA -o OUT --max-std 0.08 \\
        --cache runs/pred_cache

With ``--round-steps 0.3 --min-offset 0.15`` (and the default 16 cells) it is the product's
``flatpatches.flatten_stepped_floors``, which the pipeline runs after this study's rule: the
patches the study flattens are pinned, so the product's stage leaves them alone and a variant
is measured on the terraces it takes and the product's stage on the rest.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from stage_eval import eval_parser, run_eval_cached


def flatten_flat_terraces(lattice, vertex, pinned, max_std: float, min_cells: int,
                          log: Path | None = None, one_sided: bool = False,
                          enclosed: float = 0.0, round_steps: float = 0.0,
                          min_offset: float = 0.0):
    """Flatten, in place, the terrace patches of ``vertex`` that carry no pinned coordinate
    and whose coordinates along their axis vary by at most ``max_std`` (standard deviation)."""
    from scipy import ndimage

    from agndc_core import flatpatches as fp

    lattice = np.asarray(lattice, dtype=bool)
    for axis in range(3):
        by_mean, points, coord, pin = fp._axis_views(lattice, vertex, pinned, axis)
        for lower_inside in fp.KINDS:
            split = fp._pure_splits_last(points, lower_inside)
            patches, count = ndimage.label(split, fp._IN_PLANE)
            if count == 0:
                continue
            # fp.terrace_patches, keeping which way each patch's steps go
            below, above = fp.step_reach(split)
            steps_down = np.bincount(patches[split & below], minlength=count + 1) > 0
            steps_up = np.bincount(patches[split & above], minlength=count + 1) > 0
            terrace = steps_down | steps_up
            terrace[0] = False
            if one_sided:  # a recess floor or a plateau steps one way, a slanted plane both
                terrace &= ~(steps_down & steps_up)
            if enclosed > 0:  # the share of a patch's rim cells next to a step
                inner = ndimage.binary_erosion(split, fp._IN_PLANE, border_value=0)
                rim = split & ~inner
                rim_cells = np.bincount(patches[rim], minlength=count + 1)
                stepped = np.bincount(patches[rim & (below | above)], minlength=count + 1)
                terrace &= stepped >= enclosed * np.maximum(rim_cells, 1)
            if round_steps > 0:  # the cells along a patch's up or down steps: not one line
                terrace &= np.maximum(fp.step_roundness(patches, split & below, count),
                                      fp.step_roundness(patches, split & above, count)) \
                    >= round_steps
            cells = np.nonzero(split & terrace[patches])
            patch_of = patches[cells]
            size = np.bincount(patch_of, minlength=count + 1)
            mean, std = fp.patch_spreads(patch_of, coord[cells], count)
            taken = np.bincount(patch_of, pin[cells], count + 1) > 0
            flat = (size >= min_cells) & (std <= max_std) & ~taken
            if min_offset > 0:  # only where the network's depth is far from the midpoint
                flat &= np.abs(mean - fp.MIDPOINT) >= min_offset
            fp.set_patch_depths(coord, pin, cells, patch_of, flat[patch_of], mean,
                                by_mean[lower_inside])
            if log is not None and np.any(flat):
                with open(log, "a") as handle:
                    for p in np.flatnonzero(flat):
                        handle.write(f"{axis} {int(lower_inside)} {size[p]} {mean[p]:.3f} "
                                     f"{std[p]:.3f}\n")
    return vertex


def main() -> None:
    parser = eval_parser(__doc__, methods=False, cache=True)
    parser.add_argument("--max-std", type=float, default=0.08)
    parser.add_argument("--min-cells", type=int, default=16)
    parser.add_argument("--log", type=Path, default=None,
                        help="append each flattened patch: axis, kind, cells, mean, std")
    parser.add_argument("--one-sided", action="store_true",
                        help="only terraces whose steps all go one way (up or down)")
    parser.add_argument("--enclosed", type=float, default=0.0,
                        help="only terraces with at least this share of their rim cells next "
                        "to a step (a floor or plateau the step surrounds)")
    parser.add_argument("--round-steps", type=float, default=0.0,
                        help="only terraces whose cells next to the steps up (or down) spread "
                        "at least this ratio across their main direction (a step around a "
                        "floor, not the straight step of a tilted face)")
    parser.add_argument("--min-offset", type=float, default=0.0,
                        help="only terraces whose mean network depth lies at least this far "
                        "(in voxels) from the layer's midpoint")
    args = parser.parse_args()

    from agndc_core import flatpatches

    plain = flatpatches.fit_terraced_planes

    def fit_then_flatten(lattice, vertex, *, in_place=False, pinned=None):
        vertex = plain(lattice, vertex, in_place=in_place, pinned=pinned)
        if pinned is None:
            pinned = np.zeros(vertex.shape, dtype=bool)
        return flatten_flat_terraces(lattice, vertex, pinned, args.max_std, args.min_cells,
                                     args.log, args.one_sided, args.enclosed,
                                     args.round_steps, args.min_offset)

    flatpatches.fit_terraced_planes = fit_then_flatten
    run_eval_cached(args)


if __name__ == "__main__":
    main()
