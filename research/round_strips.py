"""A study: the flat-patch stage leaves the strips of thin round parts to the network.

    .venv/bin/python research/round_strips.py DATA -o OUT [--max-width 8] [--wall-share 0.5]
        [--no-terraced-planes]
    .venv/bin/python research/round_pins.py --round-strips 8,0.5 ...

On a binary grid, the side of an axis-aligned cylinder a few voxels in radius that faces an axis
is a strip of voxel faces a few points wide, and the layer below it crosses the surface
diagonally, so the terrace test sees no terrace and ``flatten_patches`` flattens the strip,
though the true surface sags towards its edges (docs/experiments/flat-patches.md, "Known loss").
A flat face ends at a crease: beside its edge, one layer inward, the wall is perpendicular (a
cell there is a pure split along the in-plane axis). Here a patch is **round** when it is at most
``--max-width`` cells across in its narrower in-plane direction and under ``--wall-share`` of its
edge cells (cells with an in-plane neighbour outside the patch, counted per side) have such a
wall; a round patch is left to the network like a terrace. DATA is scored as ``agndc eval``
would, with the rule in place (``stage_eval.run_eval``).
"""

from __future__ import annotations

import numpy as np
from stage_eval import eval_parser, run_eval


def pure_splits_along(points: np.ndarray, axis: int, lower_inside: bool) -> np.ndarray:
    """(A - 1, B - 1, L) bool: the cells of a slab's points (A, B, L + 1) whose four corners on
    the low side of ``axis`` (0 or 1, in the plane) are inside and four on the high side
    outside (``lower_inside``), or the reverse."""
    lower = np.take(points, range(points.shape[axis] - 1), axis=axis)
    upper = np.take(points, range(1, points.shape[axis]), axis=axis)
    column = lower & ~upper if lower_inside else ~lower & upper
    # the other in-plane axis and the split axis each take their two corners
    other = 1 - axis
    a = np.take(column, range(column.shape[other] - 1), axis=other)
    b = np.take(column, range(1, column.shape[other]), axis=other)
    pair = a & b
    return pair[..., :-1] & pair[..., 1:]


def round_strip_patches(points: np.ndarray, lower_inside: bool, split: np.ndarray,
                        patches: np.ndarray, count: int, max_width: int,
                        wall_share: float) -> np.ndarray:
    """(count + 1,) bool: the round patches (module docstring) of one kind in a slab.

    points: (A, B, L + 1) bool lattice points, split axis last; split, patches: (A - 1, B - 1,
    L) the pure splits of this kind and their patch labels (0: none)."""
    from scipy import ndimage

    inward = -1 if lower_inside else 1  # the layer on the inside of such a face
    edges = np.zeros(count + 1)
    walls = np.zeros(count + 1)
    for axis in (0, 1):
        for side, wall_lower_inside in ((1, True), (-1, False)):
            wall = pure_splits_along(points, axis, wall_lower_inside)
            # the cell beside each split cell on this side, and the one inward of it
            beside = np.roll(split, -side, axis=axis)
            below = np.roll(np.roll(wall, -side, axis=axis), -inward, axis=2)
            edge = split & ~beside
            # cells whose neighbour would lie outside the slab have no wall to test
            valid = np.ones_like(split)
            index = [slice(None)] * 3
            index[axis] = slice(-1, None) if side == 1 else slice(0, 1)
            valid[tuple(index)] = False
            index = [slice(None)] * 3
            index[2] = slice(-1, None) if inward == 1 else slice(0, 1)
            valid[tuple(index)] = False
            edges += np.bincount(patches[edge], minlength=count + 1)
            walls += np.bincount(patches[edge & below & valid], minlength=count + 1)
    width = np.full(count + 1, np.inf)  # cells across, in the narrower in-plane direction
    for label, box in enumerate(ndimage.find_objects(patches, max_label=count), start=1):
        if box is not None:
            width[label] = min(box[0].stop - box[0].start, box[1].stop - box[1].start)
    share = np.divide(walls, edges, out=np.ones(count + 1), where=edges > 0)
    round_ = (width <= max_width) & (share < wall_share)
    round_[0] = False
    return round_


def leave_to_network(round_patches) -> None:
    """Put ``flatpatches._flatten_slab`` with one line more into this process: the patches that
    ``round_patches(points, lower_inside, split, patches, count, cells, coord)`` marks ((count +
    1,) bool) are left alone, as terraces are; the other stages, which read terrace_patches
    too, are untouched."""
    from scipy import ndimage

    from agndc_core import flatpatches
    from agndc_core.flatpatches import (
        _IN_PLANE,
        _pure_splits_last,
        patch_depths,
        set_patch_depths,
        terrace_patches,
    )

    def flatten_slab(points, coord, lower_inside, written, by_mean, pin=None):
        split = _pure_splits_last(points, lower_inside)
        patches, count = ndimage.label(split, _IN_PLANE)
        if count == 0:
            return
        cells = np.nonzero(split)
        patch_of = patches[cells]
        mean = patch_depths(patch_of, coord[cells], count)
        left = terrace_patches(split, patches, count)
        left |= round_patches(points, lower_inside, split, patches, count, cells, coord)
        keep = ~left[patch_of]
        keep &= (cells[2] >= written.start) & (cells[2] < written.stop)
        set_patch_depths(coord, pin, cells, patch_of, keep, mean, by_mean)

    flatpatches._flatten_slab = flatten_slab


def enable(max_width: int, wall_share: float) -> None:
    """Put the rule into ``flatpatches._flatten_slab`` for this process."""
    leave_to_network(lambda points, lower_inside, split, patches, count, cells, coord:
                     round_strip_patches(points, lower_inside, split, patches, count, max_width,
                                         wall_share))


def quadratic_round_patches(cells, depth, patch_of, count: int, min_cells: int,
                            min_bend: float, min_share: float) -> np.ndarray:
    """(count + 1,) bool: the patches whose network depths bow like a round strip: at least
    ``min_cells`` cells, their best quadratic surface bending from their mean by at least
    ``min_bend`` voxels RMS and explaining at least ``min_share`` of their spread about it (the
    terraced planes' round test, ``flatpatches._round``, about the patch's flat mean)."""
    from agndc_core.flatpatches import _bends

    n = count + 1
    size = np.bincount(patch_of, minlength=n)
    mean = np.bincount(patch_of, depth, n) / np.maximum(size, 1)
    flat = mean[patch_of]
    spread = np.bincount(patch_of, (depth - flat) ** 2, n) / np.maximum(size, 1)
    u, v = cells[0].astype(np.float64), cells[1].astype(np.float64)
    bend = _bends(u, v, depth, flat, patch_of, n)
    round_ = (size >= min_cells) & (bend >= min_bend) & (bend ** 2 >= min_share * spread)
    round_[0] = False
    return round_


def enable_quadratic(min_cells: int, min_bend: float, min_share: float) -> None:
    """Put the quadratic rule into ``flatpatches._flatten_slab`` for this process: a patch
    whose depths bow (``quadratic_round_patches``) is left to the network like a terrace."""
    leave_to_network(lambda points, lower_inside, split, patches, count, cells, coord:
                     quadratic_round_patches(cells, coord[cells].astype(np.float64),
                                             patches[cells], count, min_cells, min_bend,
                                             min_share))


def main() -> None:
    parser = eval_parser(__doc__, methods=True)
    parser.add_argument("--max-width", type=int, default=8)
    parser.add_argument("--wall-share", type=float, default=0.5)
    parser.add_argument("--no-terraced-planes", action="store_true",
                        help="and without the terraced-planes stage (--max-width 0: that alone)")
    parser.add_argument("--quadratic", default="", metavar="CELLS,BEND,SHARE",
                        help="instead, leave the patches whose depths bow like a round strip")
    args = parser.parse_args()
    if args.quadratic:
        cells, bend, share = args.quadratic.split(",")
        enable_quadratic(int(cells), float(bend), float(share))
    else:
        enable(args.max_width, args.wall_share)
    if args.no_terraced_planes:
        from agndc_core import pipeline

        pipeline.TERRACED_PLANES = False
    run_eval(args)


if __name__ == "__main__":
    main()
