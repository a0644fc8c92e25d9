"""Where a flat patch goes in its layer: the network's mean depth, the layer's midpoint, or both.

``flatpatches.mean_depth_layers`` decides which layers' flat patches take the network's mean
depth; the others go to the middle of their layer. This study scores ``agndc eval`` with that
rule replaced:

* ``shipped``: the mean on the shape's outermost layer on each side (but along its longest
  side), the midpoint inside;
* ``mean``: the mean everywhere (the stage before the rule);
* ``midpoint``: the midpoint everywhere;
* ``outer-midpoint``: the reverse of the shipped rule;

and ``--thin N`` puts the outermost patches at the midpoint as well along an axis where the
whole shape is at most N voxels thick (thin sheets come from ``agndc val-data --sheets``),
``--far N`` along an axis where it spans more than N voxels. ``--median``: the outermost patches
take the median of the network's coordinates instead of their mean (``flatpatches.patch_depths``).
``--longest-mean``: the outermost patches of the shape's longest side keep the network's mean
too (the rule before ``flatpatches.longest_axis``); ``--longest-bounds``: no vertex of those
layers beyond mid-layer either (``snap_to_bounds`` with planes there).

    .venv/bin/python research/flat_patch_depth.py DATA --depth mean --res 64 -o OUT
    .venv/bin/python research/flat_patch_depth.py DATA --depth midpoint --shifts 3 -o OUT
    .venv/bin/python research/flat_patch_depth.py SHEETS --thin 3 --res 64 -o OUT
    .venv/bin/python research/flat_patch_depth.py DATA --median --shifts 3 -o OUT --cache DIR

docs/experiments/flat-patches.md ("Inside the shape's extent, the midpoint", "Tried and dropped",
"Thin sheets") has the numbers.
"""

from __future__ import annotations

import numpy as np
from stage_eval import eval_parser, flatten_writing, run_eval_cached


def main() -> None:
    parser = eval_parser(__doc__, cache=True)
    parser.add_argument("--depth", default="shipped",
                        choices=["shipped", "mean", "midpoint", "outer-midpoint"])
    parser.add_argument("--thin", type=int, default=0, help="midpoint on the outermost layers "
                        "too along an axis where the shape is at most this many voxels thick")
    parser.add_argument("--far", type=int, default=0, help="midpoint on the outermost layers "
                        "too along an axis where the shape spans more than this many voxels")
    parser.add_argument("--symmetric-thin", type=int, default=0, help="along an axis where the "
                        "whole shape is at most this many voxels thick, keep the network's "
                        "thickness between its two outermost flat faces but centre them on the "
                        "voxel slab (their common shift removed)")
    parser.add_argument("--longest-mean", action="store_true", help="the network's mean on "
                        "the outermost layers of the shape's longest side too, instead of the "
                        "midpoint (flatpatches.longest_axis)")
    parser.add_argument("--longest-bounds", action="store_true", help="also keep every vertex "
                        "of the longest side's outermost layers from beyond mid-layer, as "
                        "snap_to_bounds does with a mesh's bounding box")
    parser.add_argument("--ties", choices=["midpoint", "clamp"], help="the outermost layers "
                        "of every axis that ties for the longest side at the midpoint, or at "
                        "the mean but not beyond mid-layer")
    parser.add_argument("--median", action="store_true", help="the median of the network's "
                        "coordinates on the outermost patches instead of their mean")
    args = parser.parse_args()

    from agndc_core import flatpatches

    shipped = flatpatches.mean_depth_layers

    def replaced(lattice, axis):
        layers = shipped(lattice, axis)
        outer = flatpatches.outer_cell_layers(lattice, axis)
        span = outer[True] - outer[False]  # the layers of points the shape spans
        tied_mid = args.ties == "midpoint" and tied(lattice, span)
        if span <= args.thin or 0 < args.far < span or tied_mid:
            return {kind: np.zeros_like(by_mean) for kind, by_mean in layers.items()}
        if args.depth == "mean":
            return {kind: np.ones_like(by_mean) for kind, by_mean in layers.items()}
        if args.depth == "midpoint":
            return {kind: np.zeros_like(by_mean) for kind, by_mean in layers.items()}
        if args.depth == "outer-midpoint":
            return {kind: ~by_mean for kind, by_mean in layers.items()}
        return layers

    flatpatches.mean_depth_layers = replaced  # flatten_patches looks it up on every call
    if args.longest_mean:
        flatpatches.longest_axis = lambda lattice: None  # no longest side: the mean on all
    if args.symmetric_thin:
        flatten = flatpatches.flatten_patches

        def centred(lattice, vertex, *, in_place=False, pinned=None):
            out, wrote = flatten_writing(flatten, lattice, vertex, in_place, pinned)
            for axis in range(3):
                outer = flatpatches.outer_cell_layers(lattice, axis)
                if not 0 < outer[True] - outer[False] <= args.symmetric_thin:
                    continue
                coord = np.moveaxis(out[..., axis], axis, -1)
                written = np.moveaxis(wrote[..., axis], axis, -1)
                sides = [written[..., outer[kind]] for kind in (False, True)]
                if not all(side.any() for side in sides):
                    continue  # a face of the slab is not flat: nothing to centre
                # the two faces' mean departures from their layers' midpoints: their mean is
                # the common shift, their difference the network's thickness
                shift = np.mean([(coord[..., outer[kind]][side] - flatpatches.MIDPOINT).mean()
                                 for kind, side in zip((False, True), sides)])
                for kind, side in zip((False, True), sides):
                    layer = coord[..., outer[kind]]  # a view into out
                    layer[side] = np.clip(layer[side] - shift, 0.0, 1.0)
            return out

        flatpatches.flatten_patches = centred
    if args.median:
        flatpatches.patch_depths = patch_medians
    if args.longest_bounds:
        flatpatches.flatten_patches = within_longest_bounds(flatpatches.flatten_patches)
    if args.ties == "clamp":
        flatpatches.flatten_patches = tied_within_mid_layer(flatpatches.flatten_patches)
    run_eval_cached(args)


def tied(lattice, span: int) -> bool:
    """Whether an axis spanning ``span`` layers ties with another for the longest side."""
    from agndc_core import flatpatches

    spans = sorted(flatpatches.layer_spans(lattice))
    return span == spans[-1] == spans[-2]


def tied_within_mid_layer(flatten):
    """``flatten`` with the patches it places on the outermost layers of an axis that ties for
    the longest side kept from beyond mid-layer (outward: up on the upper side, down on the
    lower)."""
    from agndc_core import flatpatches

    def flatten_and_clamp(lattice, vertex, *, in_place=False, pinned=None):
        out, wrote = flatten_writing(flatten, lattice, vertex, in_place, pinned)
        lattice = np.asarray(lattice, dtype=bool)
        for axis in range(3):
            outer = flatpatches.outer_cell_layers(lattice, axis)
            if not tied(lattice, outer[True] - outer[False]):
                continue
            coord = np.moveaxis(out[..., axis], axis, -1)
            written = np.moveaxis(wrote[..., axis], axis, -1)
            for kind, limit in ((True, np.minimum), (False, np.maximum)):
                layer = coord[..., outer[kind]]  # a view into out
                side = written[..., outer[kind]]
                layer[side] = limit(layer[side], flatpatches.MIDPOINT)
        return out

    return flatten_and_clamp


def within_longest_bounds(flatten):
    """``flatten`` followed by ``flatpatches.snap_to_bounds`` with bounding planes mid-layer
    in the longest side's two outermost layers and none on the other axes."""
    from agndc_core import flatpatches

    def flatten_and_snap(lattice, vertex, *, in_place=False, pinned=None):
        out = flatten(lattice, vertex, in_place=in_place, pinned=pinned)
        lattice = np.asarray(lattice, dtype=bool)
        axis = flatpatches.longest_axis(lattice)
        if axis is None:
            return out
        outer = flatpatches.outer_cell_layers(lattice, axis)
        bounds = np.array([[-np.inf] * 3, [np.inf] * 3])
        bounds[:, axis] = outer[False] + flatpatches.MIDPOINT, outer[True] + flatpatches.MIDPOINT
        return flatpatches.snap_to_bounds(lattice, out, bounds, in_place=True, pinned=pinned)

    return flatten_and_snap


def patch_medians(patch_of: np.ndarray, values: np.ndarray, count: int) -> np.ndarray:
    """``flatpatches.patch_depths`` with the median of each patch's coordinates (0 for an
    index without cells)."""
    order = np.lexsort((values, patch_of))  # by patch, then by value
    size = np.bincount(patch_of, minlength=count + 1)
    start = np.concatenate([[0], np.cumsum(size)[:-1]])
    ordered = values[order]
    median = np.zeros(count + 1)
    has = size > 0
    low = start[has] + (size[has] - 1) // 2
    high = start[has] + size[has] // 2
    median[has] = 0.5 * (ordered[low] + ordered[high])
    return median


if __name__ == "__main__":
    main()
