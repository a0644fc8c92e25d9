"""A section through a generated layered cap (research/layered_caps.py) remeshed from its grid
alone: the true outline, marching cubes, AGNDC without the stepped floors stage and AGNDC, in
voxels. Where the cap's one-layer steps lie a few voxels apart the network draws them as a
gently tilted plane; the stepped floors stage puts the floors they run round back mid-layer.

    .venv/bin/python research/cap_section_figure.py --seed 22 -o docs/images/cap_22_section.png
"""

from __future__ import annotations

import argparse

import numpy as np


def section(vertices, faces, axis: int, at: float) -> np.ndarray:
    """(S, 2, 3) segments where the plane ``x[axis] = at`` cuts the mesh."""
    import trimesh

    normal = np.eye(3)[axis]
    return trimesh.intersections.mesh_plane(trimesh.Trimesh(vertices, faces, process=False),
                                            normal, normal * at)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seed", type=int, default=22)
    parser.add_argument("--res", type=int, default=64)
    parser.add_argument("--axis", type=int, default=1, help="the section plane's normal axis")
    parser.add_argument("--offset", type=float, default=0.013,
                        help="where the plane cuts, in the cap's own units (it spans ±0.5)")
    parser.add_argument("-o", "--out", required=True)
    args = parser.parse_args()

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from layered_caps import layered_cap

    from agndc_core import pipeline
    from agndc_core.grid import VoxelGrid
    from agndc_core.voxelize import voxelize

    vertices, faces = layered_cap(args.seed)
    voxelised = voxelize(vertices, faces, args.res)
    grid = VoxelGrid(voxelised.occupancy, affine=voxelised.affine)  # without the bounds
    voxel = np.linalg.norm(voxelised.affine[:3, 0])
    meshes = {"ground truth": (vertices, faces),
              "marching cubes": pipeline.remesh(grid, method="mc")}
    pipeline.STEPPED_FLOORS = False
    meshes["AGNDC without stepped floors"] = pipeline.remesh(grid, method="agndc", threads=1)
    pipeline.STEPPED_FLOORS = True
    meshes["AGNDC"] = pipeline.remesh(grid, method="agndc", threads=1)
    shown = [a for a in range(3) if a != args.axis]
    styles = {"ground truth": ("k", 2.0), "marching cubes": ("tab:blue", 1.0),
              "AGNDC without stepped floors": ("tab:purple", 1.0), "AGNDC": ("tab:red", 1.2)}
    figure, axes = plt.subplots(figsize=(11, 5))
    for name, mesh in meshes.items():
        points, triangles = mesh if isinstance(mesh, tuple) else (mesh.vertices, mesh.faces)
        segments = section(points, triangles, args.axis, args.offset) / voxel
        colour, width = styles[name]
        for k, segment in enumerate(segments):
            axes.plot(segment[:, shown[0]], segment[:, shown[1]], color=colour, lw=width,
                      label=name if k == 0 else None)
    axes.set_aspect(4.0)  # the layers are a voxel apart: heights drawn four times larger
    axes.grid(alpha=0.3)
    axes.legend(loc="upper right", fontsize=8)
    axes.set_title(f"cap_{args.seed}, grid alone at {args.res}³, section at "
                   f"{'xyz'[args.axis]}={args.offset} (voxels; heights ×4)")
    figure.tight_layout()
    figure.savefig(args.out, dpi=110)
    print(args.out)


if __name__ == "__main__":
    main()
