"""Check every method's output on real data: closed, outward, 2-manifold (counts per method).

    .venv/bin/python research/check_manifold.py ../shared/data/dev --res 64 128 \
        [--methods mc,mc_taubin,surfacenets,undc,agndc,agndc+bounds,oracle]
        [--checkpoint agndc=PATH]

Every dev mesh is voxelised at each resolution and every grid file (.binvox, ...) is read as is;
methods are named as for ``agndc eval`` (a plain learned method sees the grid alone, ``+bounds``
also gets the mesh's bounding box, ``LABEL=METHOD`` takes ``--checkpoint LABEL=PATH``); each
reconstruction is checked with ``meshcheck.topology_violations`` and for a positive signed
volume of the whole mesh. Prints one line per defective result and a summary table; exits with
status 1 if any result is defective.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from agndc_core.gridio import load_grid, load_mesh
from agndc_core.meshcheck import topology_violations
from agndc_core.pipeline import MESH_ONLY_METHODS, remesh, remesh_mesh
from agndc_core.study.evaluate import method_checkpoint, method_parts, parse_methods, require_meshes

GRID_SUFFIXES = (".binvox", ".vox", ".npy", ".npz", ".nii", ".nii.gz")


def signed_volume(vertices, faces) -> float:
    triangles = vertices[faces]
    return float(np.einsum("ij,ij->i", triangles[:, 0],
                           np.cross(triangles[:, 1], triangles[:, 2])).sum() / 6.0)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", type=Path)
    parser.add_argument("--res", type=int, nargs="+", default=[64, 128])
    parser.add_argument("--methods",
                        default="mc,mc_taubin,surfacenets,undc,agndc,agndc+bounds,oracle")
    parser.add_argument("--checkpoint", action="append", default=[], metavar="METHOD=PATH")
    args = parser.parse_args()
    methods = parse_methods(args.methods)
    checkpoints = dict(item.split("=", 1) for item in args.checkpoint)
    meshes = [path for path, _ in require_meshes(args.folder)]
    grids = sorted(p for p in args.folder.rglob("*") if p.name.endswith(GRID_SUFFIXES))
    jobs = [(path, res) for path in meshes for res in args.res] + [(path, None) for path in grids]
    checked, bad = {m: 0 for m in methods}, {m: 0 for m in methods}
    for path, res in jobs:
        source = load_grid(path) if res is None else load_mesh(path)
        for method in methods:
            label, base, bounded = method_parts(method)
            if res is None and base in MESH_ONLY_METHODS:
                continue  # needs a mesh
            options = dict(method=base, checkpoint=method_checkpoint(checkpoints, label, base),
                           threads=2, source_bounds=bounded)
            if res is None:
                result = remesh(source, **options)
            else:
                result = remesh_mesh(*source, resolution=res, source=path.name, **options)
            defects = {k: v for k, v in topology_violations(result.vertices, result.faces).items()
                       if v}
            volume = signed_volume(result.vertices, result.faces)
            checked[method] += 1
            if defects or volume <= 0:
                bad[method] += 1
                print(f"{path.name} @ {res or 'grid'} {method}: {defects} volume {volume:.4g}")
    print(f"\n{len(meshes)} meshes x {args.res} + {len(grids)} grid files")
    print("| method | results | defective |\n|---|---|---|")
    for method in methods:
        print(f"| {method} | {checked[method]} | {bad[method]} |")
    return 1 if any(bad.values()) else 0


if __name__ == "__main__":
    sys.exit(main())
