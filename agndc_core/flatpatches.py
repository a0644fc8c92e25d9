"""Flat patches: a flat voxel face comes out as one flat face, at the network's depth.

Where a binary grid shows a flat voxel face (a patch of cells whose corners all split the same
way along one axis), it says nothing about where the face lies inside its layer of cells: every
depth leaves the same voxels. A network's coordinate along that axis then varies from cell to
cell by its own noise, and a flat face comes back crumpled. ``flatten_patches`` gives every
cell of such a patch one coordinate along the axis, so the face is exactly flat:

- on the shape's **outermost layer** along the axis (a face that bounds the shape), the mean of
  the network's coordinates: the voxeliser frames a mesh's bounding box, so where those faces
  lie in their layer follows from the frame, and the network has learned it;
- on the outermost layers along the axis the shape spans **strictly the most layers** of
  (``longest_axis``), the layer's midpoint: ``voxelize`` puts the bounding faces of a mesh's
  longest side exactly mid-layer, which the network's mean only approximates (and a voxel
  model's faces lie there on every axis);
- **inside the shape's extent**, the layer's midpoint: where such a face lies in its layer is
  uniform over the layer for all the grid can tell, the midpoint is the best guess under that,
  and the network's mean was measured farther off (docs/experiments/flat-patches.md).

A **patch** is a set of cells in one layer, connected through shared cell faces within the
layer, each a **pure split** along the axis: its four lower corners are inside and its four
upper corners outside ("up"), or the reverse ("down"). Patches of the two kinds are separate.

A patch is left alone when it is a **terrace** of a slanted or curved surface: a pure split of
the same kind one layer up or down lies within ``tol.terrace_reach`` cells of it in the plane.
There the surface steps through the layers, and the variation of the network's coordinate
within the patch is the slope or the curvature, not noise. The terraces of a slightly tilted
plane are then fitted by one plane (``fit_terraced_planes``), which the network cannot see
across terraces tens of cells wide. A terrace that its step runs round (a floor one layer below
its rim, a plateau one layer above its ledge) is not part of a plane, whose steps are straight
lines; where the network sees it flat but off its layer's middle, it goes to the middle
(``flatten_stepped_floors``).

**Source bounds.** When the grid was voxelised from a mesh, the mesh's bounding box is known
(``VoxelGrid.source_bounds``), and it says what the grid cannot: the faces that bound the shape
lie exactly on it, and no surface lies beyond it. ``snap_to_bounds`` gives every patch of the
outermost layer of cells on each side (not a terrace, of the kind that faces outward there) the
coordinate of that side's bounding plane, and pulls every other vertex of that layer that lies
beyond the plane back onto it (the edges and corners of a bounding face). A side whose plane
lies outside its outermost layer (a part too thin to leave voxels sticks out) is left alone.

``flatten_patches_naive``, ``fit_terraced_planes_naive``, ``flatten_stepped_floors_naive`` and
``snap_to_bounds_naive`` are the slow, obviously correct references (a flood fill per patch).
"""

from __future__ import annotations

import itertools

import numpy as np
from scipy import ndimage

from .tolerances import tol

#: the two kinds of pure split: whether the lower corners (along the axis) are the inside ones
KINDS = (True, False)

#: layers of cells flattened together (memory: a few bytes per cell of a slab)
SLAB_LAYERS = 32

#: a flat face inside the shape's extent goes to the middle of its layer of cells
MIDPOINT = 0.5

#: connectivity within a layer: the 4 cells sharing a face with a cell, in the two in-plane axes
#: (the last axis is the split axis after ``np.moveaxis``)
_IN_PLANE = np.zeros((3, 3, 3), dtype=bool)
_IN_PLANE[1, 1, 1] = _IN_PLANE[0, 1, 1] = _IN_PLANE[2, 1, 1] = True
_IN_PLANE[1, 0, 1] = _IN_PLANE[1, 2, 1] = True


def flatten_patches(lattice: np.ndarray, vertex: np.ndarray, *,
                    in_place: bool = False, pinned: np.ndarray | None = None) -> np.ndarray:
    """Flatten every flat-voxel-face patch of a lattice that is not a terrace.

    Args:
        lattice: (X, Y, Z) bool, the dual-contouring lattice (grid.py).
        vertex: (X, Y, Z, 3) float, each cell's vertex as an offset from its min corner (the
            last layer along each axis holds no cell and is left as it is).
        in_place: write into ``vertex`` instead of a copy (a large grid's vertices are GBs).
        pinned: optional (X, Y, Z, 3) bool, set True at every coordinate written, so later
            stages can leave the flat faces alone (``pinned_coordinates``).

    Returns:
        (X, Y, Z, 3) float, ``vertex`` (or a copy) where the cells of every flattened patch
        share one coordinate along the patch's axis: the mean of theirs on the layers
        ``mean_depth_layers`` names (the shape's outermost but along its longest side),
        ``MIDPOINT`` elsewhere; nothing else changes.
    """
    lattice = np.asarray(lattice, dtype=bool)
    out = vertex if in_place else np.array(vertex, copy=True)
    for axis in range(3):
        by_mean, points, coord, pin = _axis_views(lattice, out, pinned, axis)
        layers = coord.shape[-1]
        # a patch lies in one layer, so slabs of layers are exact and bound the memory; each
        # slab also sees one layer beyond each end, which the terrace test reads
        for first in range(0, layers, SLAB_LAYERS):
            last = min(first + SLAB_LAYERS, layers)
            lo, hi = max(first - 1, 0), min(last + 1, layers)
            for lower_inside in KINDS:
                _flatten_slab(points[..., lo:hi + 1], coord[..., lo:hi], lower_inside,
                              range(first - lo, last - lo), by_mean[lower_inside][lo:hi],
                              None if pin is None else pin[..., lo:hi])
    return out


def _axis_views(lattice: np.ndarray, vertex: np.ndarray, pinned: np.ndarray | None, axis: int):
    """(``mean_depth_layers``, the lattice points with ``axis`` last, a (X-1, Y-1, Z-1) view of
    the cells' coordinate along ``axis`` with that axis last, the same view of ``pinned`` or
    None): what a stage that writes flat patches along one axis reads and writes."""
    points = np.moveaxis(lattice, axis, -1)  # split axis last
    coord = np.moveaxis(vertex[..., axis], axis, -1)[:-1, :-1, :-1]
    pin = None if pinned is None else np.moveaxis(pinned[..., axis], axis, -1)[:-1, :-1, :-1]
    return mean_depth_layers(lattice, axis), points, coord, pin


def patch_depths(patch_of: np.ndarray, values: np.ndarray, count: int) -> np.ndarray:
    """(count + 1,) float: the depth an outermost patch takes, the mean of its cells'
    coordinates (``patch_of``: (S,) patch of each cell in 1..count; ``values``: (S,) their
    coordinates). One function, so a study can try another statistic
    (``research/flat_patch_depth.py --median``)."""
    size = np.bincount(patch_of, minlength=count + 1)
    return np.bincount(patch_of, weights=values, minlength=count + 1) / np.maximum(size, 1)


def outer_cell_layers(lattice: np.ndarray, axis: int) -> dict[bool, int]:
    """{lower_inside: cell layer along ``axis``} of the shape's two outermost faces: the layer
    above the last occupied layer of points holds the faces whose lower corners are inside
    (True), the layer below the first occupied one the faces whose upper corners are (False);
    -1 on both for an empty lattice."""
    occupied = np.flatnonzero(lattice.any(axis=tuple(a for a in range(3) if a != axis)))
    if len(occupied) == 0:
        return {True: -1, False: -1}
    return {True: int(occupied[-1]), False: int(occupied[0]) - 1}


def layer_spans(lattice: np.ndarray) -> list[int]:
    """[x, y, z]: how many cell layers the shape spans along each axis, from its outermost
    face on one side to the other's (``outer_cell_layers``; 0 for an empty lattice)."""
    return [layers[True] - layers[False]
            for layers in (outer_cell_layers(lattice, axis) for axis in range(3))]


def longest_axis(lattice: np.ndarray) -> int | None:
    """The axis along which the occupied points span strictly more layers than along the two
    others (a mesh's longest side, where ``voxelize`` puts the bounding faces mid-layer);
    None for a tie or an empty lattice."""
    spans = layer_spans(lattice)
    longest = int(np.argmax(spans))
    if spans[longest] <= 0 or sorted(spans)[1] == spans[longest]:
        return None
    return longest


def mean_depth_layers(lattice: np.ndarray, axis: int) -> dict[bool, np.ndarray]:
    """{lower_inside: (cell layers along ``axis``,) bool}: the layers whose flat patches of
    that kind take the network's mean depth, the shape's outermost one on each side
    (``outer_cell_layers``) unless ``axis`` is the ``longest_axis``; the patches of every
    other layer go to ``MIDPOINT``."""
    layers = np.arange(lattice.shape[axis] - 1)
    if axis == longest_axis(lattice):
        return {kind: np.zeros(len(layers), dtype=bool) for kind in KINDS}
    return {kind: layers == layer for kind, layer in outer_cell_layers(lattice, axis).items()}


def _flatten_slab(points, coord, lower_inside: bool, written: range, by_mean: np.ndarray,
                  pin=None) -> None:
    """Flatten the patches of one kind in ``written`` layers of a slab, in place.

    points: (A, B, L + 1) bool lattice points of the slab, split axis last; coord: (A - 1,
    B - 1, L) float view of its cells' coordinate along the split axis; by_mean: (L,) bool,
    the slab's layers whose patches take their mean (``mean_depth_layers``; the others
    ``MIDPOINT``); pin: None or a bool view of coord's shape, set where coord is written."""
    split = _pure_splits_last(points, lower_inside)
    patches, count = ndimage.label(split, _IN_PLANE)
    if count == 0:
        return
    # from here on only the split cells (a few % of the volume) are touched
    cells = np.nonzero(split)
    patch_of = patches[cells]  # (S,) in 1..count
    mean = patch_depths(patch_of, coord[cells], count)
    keep = ~terrace_patches(split, patches, count)[patch_of]
    keep &= (cells[2] >= written.start) & (cells[2] < written.stop)  # halo layers: not ours
    set_patch_depths(coord, pin, cells, patch_of, keep, mean, by_mean)


def set_patch_depths(coord, pin, cells, patch_of, keep, mean, by_mean) -> None:
    """Give the split cells that ``keep`` selects the depth of their patch, in place: its
    ``mean`` on the layers ``by_mean`` names, ``MIDPOINT`` elsewhere; set ``pin`` (if any)
    there. ``cells``: (3,) index arrays of the split cells (split axis last); ``patch_of``, the
    patch of each; ``keep``, (S,) bool; the rest as ``_flatten_slab``'s."""
    cells = tuple(c[keep] for c in cells)
    coord[cells] = np.where(by_mean[cells[2]], mean[patch_of[keep]], MIDPOINT)
    if pin is not None:
        pin[cells] = True


def snap_to_bounds(lattice: np.ndarray, vertex: np.ndarray, bounds, *,
                   in_place: bool = False, pinned: np.ndarray | None = None) -> np.ndarray:
    """Put the flat patches that bound the shape on the source mesh's bounding planes.

    Args:
        lattice: (X, Y, Z) bool, the dual-contouring lattice (grid.py).
        vertex: (X, Y, Z, 3) float, each cell's vertex as an offset from its min corner.
        bounds: (2, 3) float, the source mesh's bounding box (min corner, max corner) in
            lattice coordinates (``VoxelGrid.world_to_index`` + ``grid.LATTICE_PAD``).
        in_place: write into ``vertex`` instead of a copy.
        pinned: optional (X, Y, Z, 3) bool, set True at the coordinate along the axis of every
            cell of each outermost layer: this stage placed them on the bounding plane or
            within it (``flatten_patches``).

    Returns:
        (X, Y, Z, 3) float, ``vertex`` (or a copy) where every patch of each side's outermost
        layer of cells that faces outward and is not a terrace has that side's plane as its
        coordinate along the axis, and no other vertex of that layer lies beyond the plane;
        nothing else changes.
    """
    lattice = np.asarray(lattice, dtype=bool)
    out = vertex if in_place else np.array(vertex, copy=True)
    for axis, lower_inside, layer, local in outermost_layers(lattice, bounds):
        inner = layer - 1 if lower_inside else layer + 1  # the next layer into the shape
        first = min(layer, inner)
        # the two cell layers' 3 point layers, split axis last
        points = np.moveaxis(lattice, axis, -1)[..., first:first + 3]
        split = _pure_splits_last(points, lower_inside)  # (A - 1, B - 1, 2)
        # (X', Y', Z') view of the layer's coordinate along the axis (split axis moved last)
        coord = np.moveaxis(out[..., axis], axis, -1)[..., layer]
        # the surface does not reach beyond its bounding box: edges and corners of the face
        clamp = np.minimum if lower_inside else np.maximum
        clamp(coord, local, out=coord)
        if pinned is not None:
            np.moveaxis(pinned[..., axis], axis, -1)[..., layer] = True
        patches, count = ndimage.label(split, _IN_PLANE)
        if count == 0:
            continue
        terrace = terrace_patches(split, patches, count)
        mine = patches[..., layer - first]
        coord[:-1, :-1][(mine > 0) & ~terrace[mine]] = local
    return out


def pinned_coordinates(vertices: np.ndarray, vertex: np.ndarray, pinned: np.ndarray):
    """Which coordinates of contoured vertices a stage pinned: (V, 3) bool.

    Args:
        vertices: (V, 3) float lattice coordinates from ``contour.dual_contour``, which puts a
            single-patch cell's vertex at cell + clip(offset, 0, 1).
        vertex: (X, Y, Z, 3) float, the offsets that were contoured; pinned: (X, Y, Z, 3) bool
            from ``flatten_patches`` / ``snap_to_bounds``.

    A coordinate is pinned when the cell that holds the vertex pinned it and the vertex lies
    exactly where that cell's offset puts it (a vertex on a cell's upper face is looked up in
    both cells that share the face). Anything else -- a cell with several patches, a vertex on
    a cell face between patches -- is not pinned.
    """
    top = np.array(vertex.shape[:3]) - 2  # the last cell along each axis
    base = np.clip(np.floor(vertices).astype(np.int64), 0, top)  # (V, 3)
    fixed = np.zeros(vertices.shape, dtype=bool)
    for axis in range(3):
        for step in (0, 1):  # the cell below too, for a vertex on a shared face
            cell = base.copy()
            cell[:, axis] -= step
            ok = cell[:, axis] >= 0
            index = tuple(cell[ok].T)
            placed = cell[ok, axis] + np.clip(vertex[index + (axis,)], 0.0, 1.0)
            fixed[np.flatnonzero(ok), axis] |= pinned[index + (axis,)] & (
                placed == vertices[ok, axis])
    return fixed


def outermost_layers(lattice: np.ndarray, bounds):
    """Yield (axis, lower_inside, layer, local) for each side of the shape whose bounding plane
    lies in its outermost layer of cells: ``layer`` is that cell layer along ``axis``, the
    outward-facing pure split there has its lower corners inside when ``lower_inside``, and the
    plane sits at ``local`` (in [0, 1]) from the layer's lower points."""
    bounds = np.asarray(bounds, dtype=np.float64).reshape(2, 3)
    for axis in range(3):
        outer = outer_cell_layers(lattice, axis)
        if outer[True] < 0:
            return  # an empty lattice
        for lower_inside, layer, plane in ((True, outer[True], bounds[1, axis]),
                                           (False, outer[False], bounds[0, axis])):
            local = plane - layer
            if 0 <= layer < lattice.shape[axis] - 1 \
                    and -tol.cell_slack <= local <= 1 + tol.cell_slack:
                yield axis, lower_inside, int(layer), float(np.clip(local, 0.0, 1.0))


def pure_splits(lattice: np.ndarray, axis: int, lower_inside: bool) -> np.ndarray:
    """(cells along the two other axes, cells along ``axis``) bool: the cells whose 4 lower
    corners along ``axis`` are all inside (``lower_inside``; outside otherwise) and whose 4
    upper corners are all the opposite. The split axis is the last one (``np.moveaxis``)."""
    return _pure_splits_last(np.moveaxis(lattice, axis, -1), lower_inside)


def _pure_splits_last(points: np.ndarray, lower_inside: bool) -> np.ndarray:
    lower, upper = points[..., :-1], points[..., 1:]
    column = lower & ~upper if lower_inside else ~lower & upper  # (X, Y, Z-1)
    # a cell's 4 corner columns, (X-1, Y-1, Z-1)
    return column[:-1, :-1] & column[1:, :-1] & column[:-1, 1:] & column[1:, 1:]


def terrace_patches(split: np.ndarray, patches: np.ndarray, count: int,
                    reach: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """(count + 1,) bool: the patches with a pure split of the same kind one layer up or down
    within ``tol.terrace_reach`` cells in the plane (index 0, no patch, is False). ``reach``:
    ``step_reach(split)`` where the caller has it already."""
    below, above = step_reach(split) if reach is None else reach
    terrace = np.zeros(count + 1, dtype=bool)
    terrace[patches[split & (below | above)]] = True
    terrace[0] = False
    return terrace


def step_reach(split: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(below, above), each bool of ``split``'s shape: the cells within ``tol.terrace_reach``
    cells in the plane of a pure split one layer down (below) or one layer up (above)."""
    near = ndimage.binary_dilation(split, _IN_PLANE, iterations=tol.terrace_reach)
    # near[..., k] marks the reach of layer k's splits
    below, above = np.zeros_like(split), np.zeros_like(split)
    below[..., 1:] = near[..., :-1]
    above[..., :-1] = near[..., 1:]
    return below, above


def flatten_stepped_floors(lattice: np.ndarray, vertex: np.ndarray, *,
                           in_place: bool = False, pinned: np.ndarray | None = None
                           ) -> np.ndarray:
    """Flatten the terraces that a step surrounds: a floor one layer below its rim, a plateau
    one layer above its ledge.

    Such a patch is a terrace (a pure split one layer away lies within reach), so
    ``flatten_patches`` leaves it to the network, and ``fit_terraced_planes`` takes it only
    when it is part of a plane. Where several one-layer steps lie a few cells apart (a cap's
    rim, recess and slot), the network reads them as a plane a few degrees off the axis, which
    gives the same grid, and places the floor up to half a voxel off
    (docs/experiments/layered-parts.md). A plane's steps are its straight contour lines; a
    floor's step runs round it. So a terrace patch that no earlier stage pinned is flattened
    when, with at least ``tol.floor_cells`` cells, the network's coordinates along its axis are
    flat (standard deviation at most ``tol.floor_flatness``), its cells next to the steps up or
    those next to the steps down are not on one line (``step_roundness`` at least
    ``tol.floor_roundness``), and their mean lies at least ``tol.floor_offset`` voxels from the
    midpoint (where the network's depth is near it, it was measured as good). The patch takes
    the depth ``flatten_patches`` gives a patch of its layer.

    Args and returns as ``flatten_patches`` (``pinned``, when given, is read too: a patch with
    a pinned coordinate is left alone).
    """
    lattice = np.asarray(lattice, dtype=bool)
    out = vertex if in_place else np.array(vertex, copy=True)
    for axis in range(3):
        by_mean, points, coord, pin = _axis_views(lattice, out, pinned, axis)
        for lower_inside in KINDS:
            _flatten_floors_of_kind(points, coord, lower_inside, by_mean[lower_inside], pin)
    return out


def _flatten_floors_of_kind(points, coord, lower_inside: bool, by_mean: np.ndarray,
                            pin=None) -> None:
    """``flatten_stepped_floors`` for the patches of one kind along one axis, in place (the
    arguments as ``_flatten_slab``'s, over the whole axis)."""
    split = _pure_splits_last(points, lower_inside)
    patches, count = ndimage.label(split, _IN_PLANE)
    if count == 0:
        return
    below, above = step_reach(split)
    terrace = terrace_patches(split, patches, count, (below, above))
    terrace &= np.maximum(step_roundness(patches, split & below, count),
                          step_roundness(patches, split & above, count)) >= tol.floor_roundness
    cells = np.nonzero(split & terrace[patches])
    patch_of = patches[cells]
    size = np.bincount(patch_of, minlength=count + 1)
    mean, spread = patch_spreads(patch_of, coord[cells], count)
    floor = (size >= tol.floor_cells) & (spread <= tol.floor_flatness) \
        & (np.abs(mean - MIDPOINT) >= tol.floor_offset)
    if pin is not None:
        floor &= np.bincount(patch_of, pin[cells], count + 1) == 0
    set_patch_depths(coord, pin, cells, patch_of, floor[patch_of], mean, by_mean)


def patch_spreads(patch_of: np.ndarray, values: np.ndarray, count: int):
    """((count + 1,) mean, (count + 1,) standard deviation) of each patch's cell ``values``
    (``patch_of``: (S,) the patch of each cell in 1..count)."""
    mean = patch_depths(patch_of, values, count)
    size = np.maximum(np.bincount(patch_of, minlength=count + 1), 1)
    square = np.bincount(patch_of, values * values, count + 1) / size
    return mean, np.sqrt(np.maximum(square - mean * mean, 0.0))


def step_roundness(patches: np.ndarray, step_cells: np.ndarray, count: int) -> np.ndarray:
    """(count + 1,) float: per patch label, the ratio of the minor to the major spread
    (standard deviation along their principal axes) of its ``step_cells`` (those near a step
    one way, ``step_reach``) in the patch's plane: 0 for cells along one straight line (a tilted
    plane's step), 1 for cells round a floor or a plateau, 0 where no step is near."""
    index = np.nonzero(step_cells)
    label = patches[index]
    u, v = (c.astype(np.float64) for c in index[:2])
    n = np.bincount(label, minlength=count + 1).astype(np.float64)
    safe = np.maximum(n, 1.0)
    mu, mv = np.bincount(label, u, count + 1) / safe, np.bincount(label, v, count + 1) / safe
    cuu = np.bincount(label, u * u, count + 1) / safe - mu * mu
    cvv = np.bincount(label, v * v, count + 1) / safe - mv * mv
    cuv = np.bincount(label, u * v, count + 1) / safe - mu * mv
    half_trace, det = (cuu + cvv) / 2, cuu * cvv - cuv * cuv
    gap = np.sqrt(np.maximum(half_trace * half_trace - det, 0.0))
    major, minor = half_trace + gap, np.maximum(half_trace - gap, 0.0)
    return np.where(n > 0, np.sqrt(minor / np.maximum(major, 1e-12)), 0.0)


def flatten_patches_naive(lattice: np.ndarray, vertex: np.ndarray) -> np.ndarray:
    """Cell-by-cell reference of ``flatten_patches`` (slow): a flood fill per patch."""
    lattice = np.asarray(lattice, dtype=bool)
    out = np.array(vertex, dtype=np.float64, copy=True)
    occupied = [[k for k in range(lattice.shape[axis]) if np.take(lattice, k, axis=axis).any()]
                for axis in range(3)]
    spans = [layers[-1] - layers[0] if layers else 0 for layers in occupied]
    for axis, lower_inside in itertools.product(range(3), KINDS):
        layers = occupied[axis]
        outer = (layers[-1] if lower_inside else layers[0] - 1) if layers else -1
        if all(spans[axis] > spans[other] for other in range(3) if other != axis):
            outer = -1  # the longest side's bounding faces: mid-layer like the inner ones
        for patch in _patches_naive(lattice, axis, lower_inside):
            if patch[0][axis] == outer:  # a face that bounds the shape
                value = np.mean([vertex[cell][axis] for cell in patch])
            else:
                value = MIDPOINT
            for cell in patch:
                out[cell][axis] = value
    return out


def snap_to_bounds_naive(lattice: np.ndarray, vertex: np.ndarray, bounds) -> np.ndarray:
    """Cell-by-cell reference of ``snap_to_bounds`` (slow)."""
    lattice = np.asarray(lattice, dtype=bool)
    out = np.array(vertex, dtype=np.float64, copy=True)
    occupied = np.argwhere(lattice)
    for axis, lower_inside in itertools.product(range(3), KINDS):
        # outward faces: up on the max side (lower corners inside), down on the min side
        if lower_inside:
            layer, plane = occupied[:, axis].max(), bounds[1][axis]
        else:
            layer, plane = occupied[:, axis].min() - 1, bounds[0][axis]
        local = plane - layer
        if not (0 <= layer < lattice.shape[axis] - 1
                and -tol.cell_slack <= local <= 1 + tol.cell_slack):
            continue
        local = min(max(local, 0.0), 1.0)
        for point in itertools.product(*(range(n) for n in lattice.shape)):
            if point[axis] == layer:  # no vertex of the layer beyond the plane
                beyond = out[point][axis] > local if lower_inside else out[point][axis] < local
                if beyond:
                    out[point][axis] = local
        for patch in _patches_naive(lattice, axis, lower_inside):
            if patch[0][axis] == layer:  # a patch lies in one layer
                for cell in patch:
                    out[cell][axis] = local
    return out


def _patches_naive(lattice: np.ndarray, axis: int, lower_inside: bool):
    """Yield each patch (a list of cells) of one axis and kind that is not a terrace."""
    for patch, terrace in _all_patches_naive(lattice, axis, lower_inside):
        if not terrace:
            yield patch


def _all_patches_naive(lattice: np.ndarray, axis: int, lower_inside: bool):
    """Yield (patch, whether it is a terrace) for each patch of one axis and kind."""
    cells = [n - 1 for n in lattice.shape]
    is_split = _split_test_naive(lattice, axis, lower_inside)
    in_plane = [a for a in range(3) if a != axis]
    seen = set()
    for start in itertools.product(*(range(n) for n in cells)):
        if start in seen or not is_split(start):
            continue
        patch, todo = [], [start]
        seen.add(start)
        while todo:
            cell = todo.pop()
            patch.append(cell)
            for a, step in itertools.product(in_plane, (-1, 1)):
                other = list(cell)
                other[a] += step
                other = tuple(other)
                if other not in seen and is_split(other):
                    seen.add(other)
                    todo.append(other)
        yield patch, _is_terrace_naive(patch, axis, in_plane, is_split)


def _split_test_naive(lattice: np.ndarray, axis: int, lower_inside: bool):
    """A function telling whether a cell (a tuple) is a pure split of the kind along ``axis``."""
    cells = [n - 1 for n in lattice.shape]

    def is_split(cell):
        if any(not 0 <= cell[a] < cells[a] for a in range(3)):
            return False
        for corner in itertools.product((0, 1), repeat=3):
            point = tuple(cell[a] + corner[a] for a in range(3))
            should_be_inside = (corner[axis] == 0) == lower_inside
            if lattice[point] != should_be_inside:
                return False
        return True

    return is_split


def _is_terrace_naive(patch, axis, in_plane, is_split) -> bool:
    return any(_steps_near_naive(cell, axis, in_plane, is_split, layer)
               for cell in patch for layer in (-1, 1))


def _steps_near_naive(cell, axis, in_plane, is_split, layer: int) -> bool:
    """Whether a pure split lies ``layer`` (-1 or 1) layers away within reach in the plane."""
    reach = tol.terrace_reach
    for da, db in itertools.product(range(-reach, reach + 1), repeat=2):
        if abs(da) + abs(db) > reach:  # the in-plane dilation reaches a diamond
            continue
        other = list(cell)
        other[in_plane[0]] += da
        other[in_plane[1]] += db
        other[axis] += layer
        if is_split(tuple(other)):
            return True
    return False


def flatten_stepped_floors_naive(lattice: np.ndarray, vertex: np.ndarray,
                                 pinned: np.ndarray | None = None) -> np.ndarray:
    """Patch-by-patch reference of ``flatten_stepped_floors`` (slow): a flood fill per patch,
    the spread of its step cells from their covariance matrix's eigenvalues."""
    lattice = np.asarray(lattice, dtype=bool)
    out = np.array(vertex, dtype=np.float64, copy=True)
    for axis, lower_inside in itertools.product(range(3), KINDS):
        in_plane = [a for a in range(3) if a != axis]
        is_split = _split_test_naive(lattice, axis, lower_inside)
        by_mean = mean_depth_layers(lattice, axis)[lower_inside]
        for patch, terrace in _all_patches_naive(lattice, axis, lower_inside):
            if not terrace or len(patch) < tol.floor_cells:
                continue
            if pinned is not None and any(pinned[cell][axis] for cell in patch):
                continue
            roundness = 0.0
            for layer in (-1, 1):
                near = [[cell[a] for a in in_plane] for cell in patch
                        if _steps_near_naive(cell, axis, in_plane, is_split, layer)]
                if near:
                    spread = np.linalg.eigvalsh(np.cov(np.array(near, float).T, bias=True))
                    spread = np.maximum(spread, 0.0)
                    roundness = max(roundness, float(np.sqrt(spread[0] / max(spread[1],
                                                                              1e-12))))
            depths = np.array([out[cell][axis] for cell in patch])
            if (roundness < tol.floor_roundness or depths.std() > tol.floor_flatness
                    or abs(depths.mean() - MIDPOINT) < tol.floor_offset):
                continue
            value = depths.mean() if by_mean[patch[0][axis]] else MIDPOINT
            for cell in patch:
                out[cell][axis] = value
    return out


def fit_terraced_planes(lattice: np.ndarray, vertex: np.ndarray, *, in_place: bool = False,
                        pinned: np.ndarray | None = None) -> np.ndarray:
    """Put the terraces of every slightly tilted plane on one plane, fitted to the network's
    vertices.

    A plane tilted a few degrees off an axis reaches a binary grid as terraces: flat patches
    (``pure_splits``) a few tens of cells wide, one layer apart. The network cannot see the
    plane across a terrace's width, so its vertices follow the steps (a 2° face came out with
    0.23 voxel RMS about its own plane, as wavy as surface nets). The terrace patches that
    reach each other (``tol.terrace_reach`` cells in the plane, in the same layer or the next,
    as ``terrace_patches`` finds terraces) form a **terraced surface**; its cells' coordinates
    along the split axis are fitted by one
    plane (least squares on the network's vertices), and the surface counts as a plane when
    that plane crosses every one of its cells within the cell's layer (``tol.terrace_slack``),
    the vertices lie within ``tol.terrace_residual`` voxels RMS of it, and their best quadratic
    surface bends away from it by at most ``tol.terrace_bend``: a curved surface steps through
    its layers unevenly or bends, and is left to the network. A surface whose vertices follow a
    curve that a quadratic surface explains (``_round``: the side of a cylinder along an axis,
    whose top terrace and a strip beside it pass the tests above) is left too. The cells of a
    plane then
    take the plane's coordinate at their own position; the one-cell risers between its terraces
    keep the network's, and the normal filter lines them up with the pinned terraces around
    them (measured: a 2°-4° face 0.005-0.008 voxel RMS about its plane; fitting the risers too
    changed nothing there and cost 0.1 % CD on the validation shapes).

    Args and returns as ``flatten_patches`` (``pinned`` set where a coordinate is written).
    """
    lattice = np.asarray(lattice, dtype=bool)
    out = vertex if in_place else np.array(vertex, copy=True)
    for axis in range(3):
        points = np.moveaxis(lattice, axis, -1)  # split axis last
        # views of the cells' offsets, split axis last: along it, then the two in-plane axes
        offsets = [np.moveaxis(out[..., a], axis, -1)[:-1, :-1, :-1]
                   for a in (axis, *(b for b in range(3) if b != axis))]
        pin = None if pinned is None else np.moveaxis(pinned[..., axis], axis, -1)[:-1, :-1, :-1]
        for lower_inside in KINDS:
            _fit_planes_of_kind(points, offsets, lower_inside, pin)
    return out


def _fit_planes_of_kind(points, offsets, lower_inside: bool, pin=None) -> None:
    """``fit_terraced_planes`` of one split axis (last) and kind, in place on ``offsets``
    ((coordinate along the axis, the two in-plane ones), each a (A, B, L) view)."""
    split = _pure_splits_last(points, lower_inside)
    patches, count = ndimage.label(split, _IN_PLANE)
    if count < 2:
        return
    terrace = terrace_patches(split, patches, count)
    cells = np.nonzero(split & terrace[patches])
    if len(cells[0]) == 0:
        return
    patch_of = patches[cells]
    surface = _terraced_surfaces(patches, terrace, cells, count)[patch_of]  # (S,) surface id
    n_surfaces = int(surface.max()) + 1
    along, u_off, v_off = (o[cells] for o in offsets)
    h = cells[2] + along  # (S,) coordinate along the axis, lattice units
    u, v = cells[0] + u_off, cells[1] + v_off
    spans = _layer_spans(cells[2], surface, n_surfaces)
    plane = _fit_planes(u, v, h, surface, n_surfaces)  # (K, 3): h = p u + q v + r
    plane = _into_layers(u, v, cells[2], plane, surface, n_surfaces, spans)
    fitted = _plane_heights(plane, surface, u, v)
    local = fitted - cells[2]  # the plane's coordinate inside each cell's layer
    outside = (local < -tol.terrace_slack) | (local > 1 + tol.terrace_slack)
    residual = np.bincount(surface, (h - fitted) ** 2, n_surfaces)
    size = np.bincount(surface, minlength=n_surfaces)
    bend = _bends(u, v, h, fitted, surface, n_surfaces)
    is_plane = (np.bincount(surface, outside, n_surfaces) == 0) & (spans >= 2) \
        & (residual <= tol.terrace_residual ** 2 * np.maximum(size, 1)) \
        & (bend <= tol.terrace_bend) \
        & ~_round(size, residual / np.maximum(size, 1), bend)
    keep = is_plane[surface]
    index = tuple(c[keep] for c in cells)
    offsets[0][index] = np.clip(local[keep], 0.0, 1.0)
    if pin is not None:
        pin[index] = True


def _round(size, mean_square, bend):
    """Whether each terraced surface is round rather than a plane seen through its terraces:
    at least ``tol.terrace_round_cells`` cells whose vertices' spread about their plane
    (``mean_square``, voxels²) is at least ``tol.terrace_round_share`` explained by their best
    quadratic surface, which bends from the plane by at least ``tol.terrace_round_bend``.

    A network that follows a tilted plane's terraces leaves a staircase about the plane, which a
    quadratic surface follows only in part; the side of a cylinder along an axis, where it faces
    another axis, reaches the grid as terraces too (its top one and a strip beside it), and the
    network's vertices follow its curve, which the quadratic surface does almost wholly.
    Arrays of one value per surface, or scalars."""
    return (np.asarray(size) >= tol.terrace_round_cells) \
        & (np.asarray(bend) >= tol.terrace_round_bend) \
        & (np.square(bend) >= tol.terrace_round_share * np.asarray(mean_square))


def _terraced_surfaces(patches, terrace, cells, count: int) -> np.ndarray:
    """(count + 1,) int: the connected terraced surface of each patch (index 0: none). Two
    terrace patches join when a cell of one lies within ``tol.terrace_reach`` cells (in the
    plane, 4-connected steps) of a cell of the other in the same layer or one layer up."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    reach = tol.terrace_reach
    shape = np.array(patches.shape)
    links = [np.zeros(0, dtype=np.int64)] * 2
    steps = [(du, dv, dl) for dl in (0, 1) for du in range(-reach, reach + 1)
             for dv in range(-(reach - abs(du)), reach - abs(du) + 1) if (du, dv, dl) != (0, 0, 0)]
    for du, dv, dl in steps:
        other = np.stack([cells[0] + du, cells[1] + dv, cells[2] + dl])
        inside = np.all((other >= 0) & (other < shape[:, None]), axis=0)
        a = patches[tuple(c[inside] for c in cells)]
        b = patches[tuple(other[:, inside])]
        hit = (b > 0) & terrace[b]
        links = [np.concatenate([links[0], a[hit]]), np.concatenate([links[1], b[hit]])]
    graph = coo_matrix((np.ones(len(links[0])), (links[0], links[1])),
                       shape=(count + 1, count + 1))
    return connected_components(graph, directed=False)[1]


def _fit_planes(u, v, h, group, n_groups: int) -> np.ndarray:
    """(n_groups, 3) least-squares planes h = p u + q v + r of each group's points (a group of
    fewer than 3 points, or of collinear ones, gets its points' mean height, p = q = 0)."""
    def total(weights):
        return np.bincount(group, weights, n_groups)

    ones = np.ones_like(u)
    # normal equations, centred on each group's mean point so they stay well conditioned
    n = np.maximum(total(ones), 1)
    mu, mv, mh = total(u) / n, total(v) / n, total(h) / n
    cu, cv, ch = u - mu[group], v - mv[group], h - mh[group]
    a = np.stack([np.stack([total(cu * cu), total(cu * cv)], -1),
                  np.stack([total(cu * cv), total(cv * cv)], -1)], -2)  # (K, 2, 2)
    b = np.stack([total(cu * ch), total(cv * ch)], -1)  # (K, 2)
    det = a[:, 0, 0] * a[:, 1, 1] - a[:, 0, 1] ** 2
    solvable = det > 1e-9 * np.maximum(a[:, 0, 0] * a[:, 1, 1], 1e-12)
    slope = np.zeros((n_groups, 2))
    safe = np.where(solvable, det, 1.0)
    slope[:, 0] = np.where(solvable, (a[:, 1, 1] * b[:, 0] - a[:, 0, 1] * b[:, 1]) / safe, 0.0)
    slope[:, 1] = np.where(solvable, (a[:, 0, 0] * b[:, 1] - a[:, 0, 1] * b[:, 0]) / safe, 0.0)
    return np.stack([slope[:, 0], slope[:, 1], mh - slope[:, 0] * mu - slope[:, 1] * mv], -1)


def _plane_heights(plane, group, u, v) -> np.ndarray:
    """(S,) height of each point's group plane h = p u + q v + r at (u, v)."""
    return plane[group, 0] * u + plane[group, 1] * v + plane[group, 2]


def _into_layers(u, v, layer, plane, group, n_groups: int, spans) -> np.ndarray:
    """(n_groups, 3) the planes, where one leaves some of its cells' layers by more than
    ``tol.terrace_slack`` and its surface covers 3 layers or more, moved towards a plane that
    crosses every cell within its layer: alternating projections (heights clipped into the
    layers, then a least-squares plane through them), at most ``tol.terrace_projections``
    passes or until the plane is within a third of the slack; kept when it ends within the
    slack. ``spans``: (n_groups,) the layers each surface covers (``_layer_spans``).

    A plane tilted 1° reaches a 128³ grid as 2-3 terraces 40-60 cells wide: the network's
    vertices follow those steps, and their least-squares plane leaves the terraces' far ends by
    up to 0.3 voxel although the true plane crosses every one of them. Two layers are left
    alone: the flat plane along their shared boundary crosses both, and would flatten a step of
    a fraction of a voxel between two flat faces. A plane that passed already, and a curved
    surface no plane fits, keep the least-squares plane."""
    def departure(planes) -> np.ndarray:  # (n_groups,) how far each leaves its layers, voxels
        fitted = _plane_heights(planes, group, u, v)
        gap = np.maximum(layer - fitted, fitted - (layer + 1))
        out = np.zeros(n_groups)
        np.maximum.at(out, group, gap)
        return out

    first = departure(plane)
    moving = (first > tol.terrace_slack) & (spans >= 3)
    active = moving.copy()  # (n_groups,) the planes still being moved
    moved = plane
    for _ in range(tol.terrace_projections):
        if not active.any():
            break
        fitted = _plane_heights(moved, group, u, v)
        refit = _fit_planes(u, v, np.clip(fitted, layer, layer + 1), group, n_groups)
        moved = np.where(active[:, None], refit, moved)
        active &= departure(moved) > tol.terrace_slack / 3
    improved = moving & (departure(moved) <= tol.terrace_slack)
    return np.where(improved[:, None], moved, plane)


def _bends(u, v, h, plane_h, group, n_groups: int) -> np.ndarray:
    """(n_groups,) how far each group's best quadratic surface h = q(u, v) departs from its
    best plane (``plane_h`` at its points): the RMS of q - plane over the group's points, in
    voxels. A tilted plane's terraces give a few hundredths (the network's steps average out);
    a gently curved surface stepping through the same layers bends by its sagitta."""
    def total(weights):
        return np.bincount(group, weights, n_groups)

    n = np.maximum(total(np.ones_like(u)), 1)
    cu, cv = u - (total(u) / n)[group], v - (total(v) / n)[group]
    scale = np.sqrt(total(cu * cu + cv * cv) / n) + 1e-9  # (K,) the group's extent
    cu, cv = cu / scale[group], cv / scale[group]
    features = np.stack([cu * cu, cu * cv, cv * cv, cu, cv, np.ones_like(cu)])  # (6, S)
    normal = np.stack([np.stack([total(a * b) for b in features], -1) for a in features], -2)
    rhs = np.stack([total(a * h) for a in features], -1)  # (K, 6)
    coefficients = np.einsum("kij,kj->ki", np.linalg.pinv(normal, rcond=1e-10), rhs)
    quadratic_h = np.sum(coefficients[group] * features.T, axis=1)  # (S,)
    return np.sqrt(total((quadratic_h - plane_h) ** 2) / n)


def _layer_spans(layer, group, n_groups: int) -> np.ndarray:
    """(n_groups,) int: how many layers each group's cells cover (max - min + 1; 0 if empty)."""
    lo = np.full(n_groups, np.iinfo(np.int64).max)
    hi = np.full(n_groups, -1)
    np.minimum.at(lo, group, layer)
    np.maximum.at(hi, group, layer)
    return np.where(hi >= 0, hi - lo + 1, 0)


def fit_terraced_planes_naive(lattice: np.ndarray, vertex: np.ndarray) -> np.ndarray:
    """Cell-by-cell reference of ``fit_terraced_planes`` (slow): flood-filled patches joined by
    a union-find, one small least-squares system per terraced surface."""
    lattice = np.asarray(lattice, dtype=bool)
    out = np.array(vertex, dtype=np.float64, copy=True)
    reach = tol.terrace_reach
    for axis, lower_inside in itertools.product(range(3), KINDS):
        in_plane = [a for a in range(3) if a != axis]
        terraces = [patch for patch, terrace in _all_patches_naive(lattice, axis, lower_inside)
                    if terrace]
        owner = {cell: i for i, patch in enumerate(terraces) for cell in patch}
        parent = list(range(len(terraces)))

        def root(i, parent=parent):
            while parent[i] != i:
                i = parent[i]
            return i

        for cell, i in owner.items():
            for du, dv, dl in itertools.product(range(-reach, reach + 1), repeat=3):
                other = list(cell)
                other[in_plane[0]] += du
                other[in_plane[1]] += dv
                other[axis] += dl
                if abs(du) + abs(dv) <= reach and dl in (0, 1) and tuple(other) in owner:
                    parent[root(i)] = root(owner[tuple(other)])
        surfaces = {}
        for cell, i in owner.items():
            surfaces.setdefault(root(i), []).append(cell)
        for cells in surfaces.values():
            u = np.array([c[in_plane[0]] + out[c][in_plane[0]] for c in cells])
            v = np.array([c[in_plane[1]] + out[c][in_plane[1]] for c in cells])
            h = np.array([c[axis] + out[c][axis] for c in cells])
            layer = np.array([c[axis] for c in cells])
            cu, cv, ch = u - u.mean(), v - v.mean(), h - h.mean()
            a = np.array([[cu @ cu, cu @ cv], [cu @ cv, cv @ cv]])
            det = np.linalg.det(a)
            slope = (np.linalg.solve(a, [cu @ ch, cv @ ch])
                     if det > 1e-9 * max(a[0, 0] * a[1, 1], 1e-12) else np.zeros(2))
            fitted = h.mean() + slope[0] * cu + slope[1] * cv
            fitted = _into_layers_naive(u, v, layer, fitted)
            local = fitted - layer
            # the best quadratic surface, on coordinates scaled by the surface's extent
            scale = np.sqrt(np.mean(cu * cu + cv * cv)) + 1e-9
            su, sv = cu / scale, cv / scale
            design = np.stack([su * su, su * sv, sv * sv, su, sv, np.ones_like(su)], -1)
            quadratic = design @ (np.linalg.pinv(design.T @ design, rcond=1e-10)
                                  @ (design.T @ h))
            spread = np.mean((h - fitted) ** 2)
            bend = np.sqrt(np.mean((quadratic - fitted) ** 2))
            if (layer.max() - layer.min() + 1 >= 2
                    and np.all((local >= -tol.terrace_slack) & (local <= 1 + tol.terrace_slack))
                    and spread <= tol.terrace_residual ** 2
                    and bend <= tol.terrace_bend
                    and not _round(len(cells), spread, bend)):
                for cell, value in zip(cells, np.clip(local, 0.0, 1.0)):
                    out[cell][axis] = value
    return out


def _into_layers_naive(u, v, layer, fitted) -> np.ndarray:
    """``_into_layers`` for one surface's cells, on the heights of its plane at them."""
    def departure(heights) -> float:
        return float(np.max(np.maximum(layer - heights, heights - (layer + 1))))

    if departure(fitted) <= tol.terrace_slack or layer.max() - layer.min() + 1 < 3:
        return fitted
    moved = fitted
    design = np.stack([u - u.mean(), v - v.mean(), np.ones_like(u)], -1)
    for _ in range(tol.terrace_projections):
        clipped = np.clip(moved, layer, layer + 1)
        moved = design @ np.linalg.lstsq(design, clipped, rcond=None)[0]
        if departure(moved) <= tol.terrace_slack / 3:
            break
    return moved if departure(moved) <= tol.terrace_slack else fitted
