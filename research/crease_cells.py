"""The cells along a flat patch's rim: the patch's depth carried one cell past its edge.

``flatpatches.flatten_patches`` gives every cell of a flat voxel-face patch one coordinate
along the patch's axis; the cells just past the patch's rim, where the face meets another
surface at a crease, keep the network's coordinate. Where such a cell's corners say the same
face goes on into it (each of its 4 corner columns along the axis is split the patch's way,
all inside or all outside, at least one split and none reversed: a convex or a concave crease
of the face), the face's plane crosses that cell too, and a sharp crease's dual vertex lies on
it. This study gives those cells the mean depth of their pinned in-plane neighbours and pins
it, then scores ``agndc eval``:

    .venv/bin/python research/crease_cells.py DATA -o OUT --cache DIR [--shifts 3]

``--rings N`` carries the depth N cells past the rim (each ring from the one before);
``--min-axes 2`` only to the cells on an edge between flat patches of two axes; ``--creases
concave`` (``convex``) only to the cells where the face meets a wall that rises from it (a
face that drops away): their other corner columns are all inside (all outside).
"""

from __future__ import annotations

import numpy as np
from stage_eval import eval_parser, flatten_writing, run_eval_cached


def carry_to_creases(lattice: np.ndarray, vertex: np.ndarray, pinned: np.ndarray,
                     flat: np.ndarray, rings: int = 1, min_axes: int = 1,
                     moved: np.ndarray | None = None, creases: str = "both") -> int:
    """Give the crease cells next to the flattened patches their patch's depth, in place.

    lattice: (X, Y, Z) bool; vertex: (X, Y, Z, 3) float offsets; pinned: (X, Y, Z, 3) bool,
    set where a coordinate is written; flat: (X, Y, Z, 3) bool, the coordinates
    ``flatten_patches`` wrote (the patches the depth is carried from); min_axes: a cell takes
    the depths only when it is a crease cell of patches along at least this many axes (2: an
    edge between two flat faces); moved: None, or (X, Y, Z, 3) float, how far the stage moved
    each coordinate it wrote (its depth less the network's): a crease cell is then moved by
    its neighbours' mean move instead of taking their depth, and is not pinned (the rim
    follows its face); creases: "both", or "concave" / "convex" for the cells whose other
    corner columns are all inside / all outside only. Returns the number of coordinates
    written."""
    from agndc_core.flatpatches import _pure_splits_last

    take_all = np.zeros(vertex.shape, dtype=bool)
    value_all = np.zeros(vertex.shape)
    for axis in range(3):
        points = np.moveaxis(lattice, axis, -1)
        coord = np.moveaxis(vertex[..., axis], axis, -1)[:-1, :-1, :-1].copy()
        pin = np.moveaxis(pinned[..., axis], axis, -1)[:-1, :-1, :-1].copy()
        took = np.moveaxis(take_all[..., axis], axis, -1)[:-1, :-1, :-1]
        value = np.moveaxis(value_all[..., axis], axis, -1)[:-1, :-1, :-1]
        source = np.moveaxis(flat[..., axis], axis, -1)[:-1, :-1, :-1].copy()
        carried = coord if moved is None else \
            np.moveaxis(moved[..., axis], axis, -1)[:-1, :-1, :-1].copy()
        lower, upper = points[..., :-1], points[..., 1:]
        for lower_inside in (True, False):
            split_col = lower & ~upper if lower_inside else ~lower & upper
            reversed_col = ~lower & upper if lower_inside else lower & ~upper
            corners = [(slice(None, -1), slice(None, -1)), (slice(1, None), slice(None, -1)),
                       (slice(None, -1), slice(1, None)), (slice(1, None), slice(1, None))]
            any_split = np.zeros(coord.shape, dtype=bool)
            any_reversed = np.zeros(coord.shape, dtype=bool)
            any_inside = np.zeros(coord.shape, dtype=bool)
            any_outside = np.zeros(coord.shape, dtype=bool)
            for a, b in corners:
                any_split |= split_col[a, b]
                any_reversed |= reversed_col[a, b]
                any_inside |= (lower & upper)[a, b]
                any_outside |= (~lower & ~upper)[a, b]
            all_split = _pure_splits_last(points, lower_inside)  # the patches' own cells
            crease = any_split & ~all_split & ~any_reversed
            if creases == "concave":
                crease &= any_inside & ~any_outside
            elif creases == "convex":
                crease &= any_outside & ~any_inside
            have = source & all_split
            for _ in range(rings):
                total = np.zeros(coord.shape)
                count = np.zeros(coord.shape)
                for shift in ((1, 0), (-1, 0), (0, 1), (0, -1)):
                    rolled_have = _shifted(have, shift)
                    total += np.where(rolled_have, _shifted(carried, shift), 0.0)
                    count += rolled_have
                take = crease & (count > 0) & ~pin
                if moved is None:
                    coord[take] = total[take] / count[take]
                else:
                    carried[take] = total[take] / count[take]
                    coord[take] = np.clip(coord[take] + carried[take], 0.0, 1.0)
                pin[take] = True
                took[take] = True
                value[take] = coord[take]
                have = have | take
    take_all &= (take_all.sum(axis=-1) >= min_axes)[..., None]
    vertex[take_all] = value_all[take_all]
    if moved is None:
        pinned |= take_all
    return int(take_all.sum())


def patch_mean_moves(lattice: np.ndarray, moved: np.ndarray, flat: np.ndarray) -> np.ndarray:
    """``moved`` with each flattened patch's cells given their patch's mean move."""
    from scipy import ndimage

    from agndc_core.flatpatches import _IN_PLANE, _pure_splits_last

    out = np.array(moved, copy=True)
    for axis in range(3):
        points = np.moveaxis(lattice, axis, -1)
        view = np.moveaxis(out[..., axis], axis, -1)[:-1, :-1, :-1]
        source = np.moveaxis(flat[..., axis], axis, -1)[:-1, :-1, :-1]
        for lower_inside in (True, False):
            cells = source & _pure_splits_last(points, lower_inside)
            patches, count = ndimage.label(cells, _IN_PLANE)
            if count == 0:
                continue
            size = np.bincount(patches[cells], minlength=count + 1)
            total = np.bincount(patches[cells], weights=view[cells], minlength=count + 1)
            view[cells] = (total / np.maximum(size, 1))[patches[cells]]
    return out


def _shifted(values: np.ndarray, shift) -> np.ndarray:
    """values moved by ``shift`` cells along the first two axes, zero (False) where nothing
    comes in: out[i, j] = values[i - di, j - dj]."""
    out = np.zeros_like(values)
    di, dj = shift
    src = [slice(None)] * 2
    dst = [slice(None)] * 2
    for k, d in enumerate((di, dj)):
        if d > 0:
            src[k], dst[k] = slice(None, -d), slice(d, None)
        elif d < 0:
            src[k], dst[k] = slice(-d, None), slice(None, d)
    out[tuple(dst)] = values[tuple(src)]
    return out


def main() -> None:
    parser = eval_parser(__doc__, cache=True)
    parser.add_argument("--rings", type=int, default=1)
    parser.add_argument("--min-axes", type=int, default=1, help="2: only cells on an edge "
                        "between flat patches of two axes")
    parser.add_argument("--follow", action="store_true", help="move the crease cells as far "
                        "as their patch moved, instead of giving them its depth")
    parser.add_argument("--patch-move", action="store_true", help="with --follow: each "
                        "crease cell moves as far as its patches' mean moved, not its "
                        "neighbours")
    parser.add_argument("--creases", choices=["both", "concave", "convex"], default="both",
                        help="the crease cells of walls rising from the face, of faces "
                        "dropping away, or both")
    args = parser.parse_args()

    from agndc_core import flatpatches

    flatten = flatpatches.flatten_patches

    def with_creases(lattice, vertex, *, in_place=False, pinned=None):
        network = np.array(vertex, copy=True)
        mine = np.zeros(vertex.shape, dtype=bool) if pinned is None else pinned
        out, flat = flatten_writing(flatten, lattice, vertex, in_place, mine)
        lattice = np.asarray(lattice, dtype=bool)
        moved = out - network
        if args.patch_move:
            moved = patch_mean_moves(lattice, moved, flat)
        carry_to_creases(lattice, out, mine, flat, args.rings, args.min_axes,
                         moved if args.follow else None, args.creases)
        return out

    flatpatches.flatten_patches = with_creases  # the pipeline looks it up at each call
    run_eval_cached(args)


if __name__ == "__main__":
    main()
