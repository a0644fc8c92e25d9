"""Every numeric tolerance of the package, named in one place with the reason for its value."""

from dataclasses import dataclass


@dataclass
class Tolerances:
    # offsets of the parity rays from lattice lines, in grid units: irrational-looking so that rays
    # never pass exactly through mesh vertices or edges of axis-aligned CAD parts
    ray_jitter: tuple = (1.3717e-5, 2.9311e-5)
    # Tikhonov pull of the QEF towards the mass point of the cell's samples (UNDC uses 1e-6 then
    # grows it until the vertex is inside the cell); relative to the QEF's trace
    qef_pull: float = 1e-6
    # QEF eigenvalues below this fraction of the largest are treated as zero (flat or edge cells)
    qef_singular: float = 0.05
    # a cell counts as "containing" a sample if it is inside the cell dilated by this (grid units)
    cell_slack: float = 1e-9
    # a cell lies on an axis-aligned face when the mean squared normal component along one axis
    # (its quadric's diagonal) exceeds this: the normal is within 0.6 deg of the axis, so the
    # face crosses no voxel layer over ~100 voxels and the binary grid cannot place it in depth
    axis_aligned: float = 0.9999
    # a flat voxel-face patch is a terrace of a slanted or curved surface (and is not flattened,
    # flatpatches.py) when a same-kind patch one layer up or down lies within this many cells in
    # the plane. Measured on the dev meshes at 64³ (agndc CD): 1 misses terraces (4.115, worse
    # than not flattening, 4.048); 2, 3 and 5 give 4.032-4.033; 3 keeps the best edges (ECD)
    terrace_reach: int = 3
    # a terraced surface is a plane (flatpatches.fit_terraced_planes) when its fitted plane
    # crosses every one of its cells within the cell's layer, give or take this many voxels...
    # (chosen on 24 generated validation shapes at 64³: 0.1 rejected a box's face tilted 4° for
    # one cell at 0.107; 0.15 and 0.25 gave the same CD, 0.15 the better edges;
    # docs/experiments/terraced-planes.md)
    terrace_slack: float = 0.15
    # ... and the network's vertices lie within this many voxels RMS of it (a staircase followed
    # step by step has ~0.29)
    terrace_residual: float = 0.35
    # ... and its best quadratic surface departs from the plane by at most this many voxels RMS
    # (a gently curved surface through the same layers is not flattened; a tilted face with
    # only 2-3 terraces bends its quadratic fit by up to 0.25 following the steps)
    terrace_bend: float = 0.3
    # ... and it is not round: a surface of at least terrace_round_cells cells whose vertices'
    # spread about the plane is at least terrace_round_share explained by a quadratic surface
    # bending from it by at least terrace_round_bend voxels RMS (flatpatches._round). Chosen on
    # a frame of plates with pins along the axes and the validation family at 64³ (pins 6.905 ->
    # 6.836, family 6.973 -> 6.972; share 0.95 or 30 cells and 0.85 no better;
    # docs/experiments/terraced-planes.md, "Round sides left round")
    terrace_round_cells: int = 50
    terrace_round_bend: float = 0.1
    terrace_round_share: float = 0.9
    # passes of alternating projections that move a terraced surface's least-squares plane
    # into its cells' layers (flatpatches._into_layers)
    terrace_projections: int = 100
    # a learned component enclosing less than this share of its surface nets volume is squashed
    # flat (contour.restore_folded_components) and takes the surface nets vertices; a lone voxel
    # the network shrinks keeps a sizeable share (a squashed one had 3e-15)
    fold_volume: float = 1e-3
    # a terrace that a step surrounds (a recessed floor, a plateau on a ledge) goes to its
    # layer's midpoint (flatpatches.flatten_stepped_floors) when the network sees it flat: its
    # coordinates have at most this standard deviation, in voxels...
    floor_flatness: float = 0.08
    # ... its cells next to the steps up, or those next to the steps down, spread at least this
    # ratio across their main direction (a tilted plane's steps are straight lines: ~0)...
    floor_roundness: float = 0.3
    # ... and their mean lies at least this many voxels from the midpoint; with at least
    # floor_cells cells. Chosen on the validation family, its thin sheets and layered caps at
    # 64³ (0.1 and 0.15 tie on the caps, 0.15 is level on the family; with no offset bound a
    # large face whose network depth was right moved; docs/experiments/layered-parts.md)
    floor_offset: float = 0.15
    floor_cells: int = 16
    # quad output (quads.py): two triangles of a dual-contouring quad are joined when each far
    # vertex lies within this many voxels of the other triangle's plane
    quad_planar: float = 0.05
    # ... and every corner of the quad turns by more than this sine (about 1 degree): no fold,
    # no bow tie, no straight corner
    quad_corner: float = 0.0175


tol = Tolerances()
