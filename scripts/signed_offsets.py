"""Signed distance of a method's output vertices to the true surface, along the true normal.

    python scripts/signed_offsets.py MESH RES METHOD_OR_CHECKPOINT [...]

Voxelises MESH at RES, reconstructs it with each method (``mc``, ``surfacenets``, ``undc``,
``agndc``, or a ``.safetensors`` AGNDC checkpoint) and prints, in voxels and outward positive, the
mean signed offset of the vertices: all of them, those nearest an axis-aligned face of the true
mesh (where binary input cannot place a face inside its voxel, so the unbiased guess is surface
nets' midpoint) and the rest. A method that pushes faces outward or inward shows it here even when
its mean distance looks fine.
"""

import argparse

import numpy as np
import trimesh

from agndc_core.gridio import load_mesh
from agndc_core.pipeline import remesh_mesh


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("mesh")
    parser.add_argument("res", type=int)
    parser.add_argument("methods", nargs="+")
    args = parser.parse_args()
    vertices, faces = load_mesh(args.mesh)
    truth = trimesh.Trimesh(vertices, faces, process=False)
    voxel = np.ptp(vertices, 0).max() / args.res
    print(f"{args.mesh}: extent {np.round(np.ptp(vertices, 0) / voxel, 2)} voxels")
    for name in args.methods:
        checkpoint = name if name.endswith(".safetensors") else None
        result = remesh_mesh(vertices, faces, resolution=args.res,
                             method="agndc" if checkpoint else name, checkpoint=checkpoint)
        closest, _, triangle = trimesh.proximity.closest_point(truth, result.vertices)
        normal = truth.face_normals[triangle]
        signed = np.einsum("ij,ij->i", result.vertices - closest, normal) / voxel
        aligned = np.abs(normal).max(axis=1) > 0.999
        print(f"{name[-32:]:>32}  all {signed.mean():+.3f}  "
              f"axis-aligned faces {signed[aligned].mean():+.3f} (|s| "
              f"{np.abs(signed[aligned]).mean():.3f}, {aligned.mean():.0%} of vertices)  "
              f"other {signed[~aligned].mean():+.3f} (|s| {np.abs(signed[~aligned]).mean():.3f})")


if __name__ == "__main__":
    main()
