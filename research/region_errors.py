"""Where on a mesh a method's Chamfer distance comes from: the CD split by region of the ground
truth, and the offsets of its large axis-aligned faces.

    .venv/bin/python research/region_errors.py MESH --methods mc,undc,agndc [--shift X,Y,Z]

Each method remeshes the mesh's grid alone (no bounding box) at ``--res``, on the centred grid or
moved by ``--shift`` (voxels, as ``agndc eval --shifts`` moves it). Printed per method:

* the CD×10⁵ (the metrics' normalised frame, each surface sampled ``--samples`` times, the sum
  of the two directions' mean squared distances) and its parts by the region of the nearest
  ground-truth sample: faces whose normal points up or down the mesh's thinnest axis (``up``,
  ``down``), the others (``side``); then near a sharp edge (within 1.5 voxels of a sample of
  ``metrics.edge_points``), on axis-aligned faces away from edges (``flat``), the rest
  (``other``). Each part is its share of the total, so the parts add up to the CD;
* for each plane of the ground truth perpendicular to the thinnest axis (every axis with
  ``--all-axes``) with at least 1 % of its area (upward and downward faces apart), the median
  offset along the axis (voxels, positive up) from its samples to the nearest output samples:
  ``--planes``;
* with ``--heights N``, the CD's parts in N equal slabs of height along ``--height-axis`` (0-2,
  default the thinnest), lowest first, and the two directions apart (ground truth to output,
  output to ground truth): where along a row of cones the tips lose.

docs/experiments/flat-terraces.md and the README's results use it on `abc8`, `1004825` and
`20mm-xyz-cube`.
"""

from __future__ import annotations

import argparse

import numpy as np

#: a sample is near an edge within this many voxels of an edge sample
EDGE_REACH = 1.5
#: a face is axis-aligned when a component of its normal exceeds this
AXIS_ALIGNED = 0.99
#: a face points up or down the thinnest axis when that component exceeds this
FACING = 0.7


def region_parts(d_gt, d_pred, nearest_gt, regions: dict[str, np.ndarray]) -> dict[str, float]:
    """{region: its part of the CD}: ``d_gt`` (n,) distances of the ground-truth samples to the
    output, ``d_pred`` (m,) of the output samples to the ground truth, ``nearest_gt`` (m,) the
    ground-truth sample nearest each output sample, ``regions`` {name: (n,) bool} over the
    ground-truth samples. The parts of a partition add up to mean(d_gt²) + mean(d_pred²)."""
    return {name: float(np.sum(d_gt[mask] ** 2) / len(d_gt)
                         + np.sum(d_pred[mask[nearest_gt]] ** 2) / len(d_pred))
            for name, mask in regions.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("mesh")
    parser.add_argument("--methods", default="mc,undc,agndc")
    parser.add_argument("--res", type=int, default=64)
    parser.add_argument("--shift", default="0,0,0", help="X,Y,Z sub-voxel shift of the grid")
    parser.add_argument("--samples", type=int, default=100_000)
    parser.add_argument("--planes", action="store_true")
    parser.add_argument("--all-axes", action="store_true", help="--planes perpendicular to every "
                        "axis, not only the thinnest")
    parser.add_argument("--heights", type=int, default=0, help="slabs of height, 0: none")
    parser.add_argument("--height-axis", type=int, default=None)
    args = parser.parse_args()

    from scipy.spatial import cKDTree

    from agndc_core.gridio import load_mesh
    from agndc_core.metrics import edge_points, normalization, sample_surface
    from agndc_core.pipeline import remesh_mesh
    from agndc_core.voxelize import voxelize

    vertices, faces = load_mesh(args.mesh)
    shift = tuple(float(s) for s in args.shift.split(","))
    centre, scale = normalization(vertices)
    # the grid's voxel in the normalised frame (the longest side is one unit, and the
    # voxeliser's margin is counted inside the resolution)
    grid = voxelize(vertices, faces, args.res, shift=shift)
    voxel = float(np.abs(grid.affine[0, 0])) / scale
    gt, gt_normal = sample_surface((vertices - centre) / scale, faces, args.samples,
                                   np.random.default_rng(0))
    axis = int(np.argmin(np.ptp(vertices, axis=0)))
    edge = np.zeros(len(gt), dtype=bool)
    edge[edge_points(gt, gt_normal)] = True
    near_edge = cKDTree(gt[edge]).query(gt)[0] < EDGE_REACH * voxel if edge.any() \
        else np.zeros(len(gt), dtype=bool)
    aligned = np.abs(gt_normal).max(axis=1) > AXIS_ALIGNED
    facing = gt_normal[:, axis]
    splits = [{"up": facing > FACING, "down": facing < -FACING,
               "side": np.abs(facing) <= FACING},
              {"edge": near_edge, "flat": ~near_edge & aligned, "other": ~near_edge & ~aligned}]
    slab_axis = axis if args.height_axis is None else args.height_axis
    if args.heights:
        level = gt[:, slab_axis]
        edges = np.linspace(level.min(), level.max(), args.heights + 1)
        slab = np.clip(np.searchsorted(edges, level, side="right") - 1, 0, args.heights - 1)
        splits.append({f"h{k}": slab == k for k in range(args.heights)})
    planes = []  # (axis, level, facing up): an upward and a downward face can share a level
    for plane_axis in range(3) if args.all_axes else (axis,):
        height = np.round(gt[:, plane_axis] / voxel, 2)
        for up in (True, False):
            along = gt_normal[:, plane_axis]
            on_plane = along > AXIS_ALIGNED if up else along < -AXIS_ALIGNED
            levels, counts = np.unique(height[on_plane], return_counts=True)
            planes += [(plane_axis, level, up, on_plane & (height == level))
                       for level in levels[counts >= 0.01 * len(gt)]]
    print(f"{args.mesh}: thinnest axis {axis}, {edge.sum()} edge samples, shift {shift}")
    for method in args.methods.split(","):
        result = remesh_mesh(vertices, faces, resolution=args.res, method=method,
                             source="region_errors", shift=shift, source_bounds=False)
        out, _ = sample_surface((result.vertices - centre) / scale, result.faces, args.samples,
                                np.random.default_rng(1))
        out_tree = cKDTree(out)
        d_gt, _ = out_tree.query(gt)
        d_out, nearest = cKDTree(gt).query(out)
        line = f"{method:14s} CD {1e5 * (np.mean(d_gt ** 2) + np.mean(d_out ** 2)):.3f} |"
        for split in splits:
            parts = region_parts(d_gt, d_out, nearest, split)
            line += " " + " ".join(f"{name} {1e5 * part:.3f}" for name, part in parts.items())
            line += " |"
        if args.heights:
            line += (f" gt→out {1e5 * np.mean(d_gt ** 2):.3f}"
                     f" out→gt {1e5 * np.mean(d_out ** 2):.3f} |")
        print(line)
        if args.planes:
            for plane_axis, level, up, mask in planes:
                offset = (out[out_tree.query(gt[mask])[1], plane_axis]
                          - gt[mask, plane_axis]) / voxel
                print(f"    {'up' if up else 'down'}-facing plane of axis {plane_axis} at "
                      f"{level:+.2f} voxels ({mask.sum()} samples): median offset "
                      f"{np.median(offset):+.3f}")


if __name__ == "__main__":
    main()
