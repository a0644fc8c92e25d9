"""Signed distance of a method's output vertices to the true surface, along the true normal.

    python research/signed_offsets.py MESH RES METHOD_OR_CHECKPOINT [...]
    python research/signed_offsets.py --samples FOLDER METHOD_OR_CHECKPOINT [...]

The first form voxelises MESH at RES; the second takes held-out training samples
(``agndc train-data``: their lattices, frames and true meshes). Each method (``surfacenets``,
``agndc``, or a ``.safetensors`` AGNDC checkpoint; with a mesh also ``mc`` and ``undc``)
reconstructs the grid. The script prints, in voxels and outward positive, the mean signed offset
and the mean absolute offset of the vertices. It splits them into those nearest an axis-aligned
face of the true mesh and the rest. On an axis-aligned face, binary input cannot place the face
inside its voxel, so the unbiased guess is surface nets' midpoint. A method that pushes faces out
or in shows it in the mean. One that scatters them shows it in the mean absolute offset.
"""

import argparse
from pathlib import Path

import numpy as np
import trimesh

from agndc_core.tolerances import tol

METHODS_ON_LATTICES = ("surfacenets", "agndc")


def offsets(vertices, truth: trimesh.Trimesh, voxel: float):
    """(signed offsets on axis-aligned faces, signed offsets elsewhere), in voxels."""
    closest, _, triangle = trimesh.proximity.closest_point(truth, vertices)
    normal = truth.face_normals[triangle]
    signed = np.einsum("ij,ij->i", vertices - closest, normal) / voxel
    # the labels' test (tol.axis_aligned on the quadric's diagonal) for a single face's normal
    aligned = (normal**2).max(axis=1) > tol.axis_aligned
    return signed[aligned], signed[~aligned]


def summary(name: str, aligned: np.ndarray, other: np.ndarray) -> str:
    def part(s):
        return f"{s.mean():+.3f} (|s| {np.abs(s).mean():.3f})" if len(s) else "  none"
    share = len(aligned) / max(1, len(aligned) + len(other))
    return (f"{name[-32:]:>32}  axis-aligned faces {part(aligned)}, {share:.0%} of vertices;  "
            f"other {part(other)}")


def on_mesh(path, res, methods) -> None:
    from agndc_core.gridio import load_mesh
    from agndc_core.pipeline import remesh_mesh

    vertices, faces = load_mesh(path)
    truth = trimesh.Trimesh(vertices, faces, process=False)
    voxel = np.ptp(vertices, 0).max() / res
    print(f"{path}: extent {np.round(np.ptp(vertices, 0) / voxel, 2)} voxels")
    for name in methods:
        checkpoint = name if name.endswith(".safetensors") else None
        result = remesh_mesh(vertices, faces, resolution=res,
                             method="agndc" if checkpoint else name, checkpoint=checkpoint)
        print(summary(name, *offsets(result.vertices, truth, voxel)))


def on_samples(folder, methods) -> None:
    from agndc_core.checkpoint import default_checkpoint_path, load_checkpoint
    from agndc_core.contour import dual_contour
    from agndc_core.grid import lattice_to_world
    from agndc_core.labels import crossed_edges
    from agndc_core.surfacenets import surface_nets_lattice
    from agndc_core.training.data import load_sample, sample_mesh
    from agndc_core.training.validate import reconstruct_sample

    models = {}
    for name in methods:
        if name.endswith(".safetensors") or name == "agndc":
            path = name if name != "agndc" else default_checkpoint_path("agndc")
            models[name] = load_checkpoint(path)[0].eval()
        elif name != "surfacenets":
            raise SystemExit(f"--samples takes {', '.join(METHODS_ON_LATTICES)} or checkpoints")
    found = {name: ([], []) for name in methods}
    paths = sorted(Path(folder).glob("sample_*.npz"))
    for path in paths:
        sample = load_sample(path)
        truth = trimesh.Trimesh(*sample_mesh(sample), process=False)
        voxel = float(np.linalg.norm(sample["affine"][:3, 0]))
        lattice = sample["lattice"]
        for name in methods:
            if name == "surfacenets":
                vertices, _ = dual_contour(surface_nets_lattice(lattice),
                                           crossed_edges(lattice), lattice)
                vertices = lattice_to_world(vertices, sample["affine"])
            else:  # exactly as the trainer's validation reconstructs a sample
                vertices, _ = reconstruct_sample(models[name], sample)
            for kept, new in zip(found[name], offsets(vertices, truth, voxel)):
                kept.append(new)
    print(f"{folder}: {len(paths)} samples")
    for name, (aligned, other) in found.items():
        print(summary(name, np.concatenate(aligned), np.concatenate(other)))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--samples", help="a folder of held-out samples instead of a mesh")
    parser.add_argument("args", nargs="+", help="MESH RES METHODS... or, with --samples, METHODS")
    args = parser.parse_args()
    if args.samples:
        on_samples(args.samples, args.args)
    else:
        on_mesh(args.args[0], int(args.args[1]), args.args[2:])


if __name__ == "__main__":
    main()
