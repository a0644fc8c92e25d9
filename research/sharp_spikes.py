"""Spikes and notches of Sharp (``method="sharp"``): how far its vertices leave the source
surface and how many of its faces turn away from every source normal near them.

    .venv/bin/python research/sharp_spikes.py measure --res 64 --tag after [--shapes NAMES]
    .venv/bin/python research/sharp_spikes.py render --res 64 --tags before after
    .venv/bin/python research/sharp_spikes.py export --out /tmp/sharp_shapes  # for agndc eval

Shapes: the bevelled cube and generated CAD parts (``agndc_core.study.shapes``), a plate with a
boss, a through-hole and a block turned off the grid axes (junctions and hole rims), and the
CAD and Thingi10K dev meshes (``../shared/data/dev``). Measured in the lattice frame, one unit
per voxel (trimesh's closest-point tolerances are absolute, so a source in millimetres would
be measured wrongly in its own units):

* vertex distance: each output vertex to the source surface (max, 99.9th percentile, count
  over 0.25 and 0.5 voxel);
* turned faces: output faces whose normal is more than 30 (60) degrees from every source
  normal within 0.75 voxel of the face's centre (a crease cut across, a spike's flank, a
  notch's walls); a face along a true crease has one of its two sides' normals nearby.

``measure`` writes ``out/sharp_spikes/rows_<res>_<tag>.csv`` and the meshes, ``render`` draws the
places where the first tag has its worst turned faces next to the same places in the other
tags (turned faces red, the source's creases black); docs/images/sharp_notches_junction_64.png is

    .venv/bin/python research/sharp_spikes.py render --res 64 --tags before after \
        --shapes junction1 --place 1 --out docs/images/sharp_notches_junction_64.png

where ``before`` is ``measure`` run with labels whose QEF held surface samples only (and pulled
outside solutions towards the mass point), ``after`` with the current labels.
"""

from __future__ import annotations

import argparse
import csv
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # a script: the checkout's agndc_core, installed or not

DATA = ROOT.parent / "shared" / "data" / "dev"
OUT = ROOT / "out" / "sharp_spikes"
#: generated CAD parts: the first CAD-family seeds from this one on
CAD_SEEDS = 12
#: a face is turned when every source normal near it is further than this (degrees)
TURNED = (30.0, 60.0)
#: "near": source samples within this many voxels of the face's centre
NEAR = 0.75
#: spacing of the source samples that stand for its normals (voxels)
NORMAL_SPACING = 0.2


def junction_part(seed: int = 1, segments: int = 32):
    """A plate with a cylindrical boss, a through-hole and a block, turned by a seeded random
    rotation: concave junctions, hole rims and corners where three creases meet, off-grid."""
    from manifold3d import Manifold
    from scipy.spatial.transform import Rotation

    plate = Manifold.cube((1.0, 0.7, 0.15), center=True)
    boss = Manifold.cylinder(0.25, 0.12, 0.12, segments).translate((-0.2, 0.0, 0.05))
    hole = Manifold.cylinder(0.5, 0.08, 0.08, segments).translate((0.25, 0.05, -0.25))
    block = Manifold.cube((0.15, 0.15, 0.2), center=True).translate((0.3, -0.2, 0.1))
    turn = Rotation.random(random_state=seed).as_matrix()
    mesh = (plate + boss - hole + block).transform(np.hstack([turn, np.zeros((3, 1))])).to_mesh()
    return np.asarray(mesh.vert_properties[:, :3], np.float64), np.asarray(mesh.tri_verts, np.int64)


def shapes(names=None):
    """(name, vertices, faces) of every measured shape (or of those in ``names``)."""
    from agndc_core.gridio import load_mesh
    from agndc_core.study.shapes import bevelled_cube, generate_shape, shape_family

    def wanted(name):
        return names is None or name in names

    if wanted("bevelled_cube"):
        yield "bevelled_cube", *bevelled_cube()
    for seed in (1, 2):
        if wanted(f"junction{seed}"):
            yield f"junction{seed}", *junction_part(seed)
    seeds = [s for s in range(200) if shape_family(s) == "cad"][:CAD_SEEDS]
    for seed in seeds:
        if wanted(f"cad{seed}"):
            yield f"cad{seed}", *generate_shape(seed)
    with open(DATA / "MANIFEST.csv", newline="") as handle:
        for row in csv.DictReader(handle):
            name = Path(row["file"]).stem
            if row["kind"] in ("cad", "print (Thingi10K)") and wanted(name):
                yield name, *load_mesh(DATA / row["file"])


def turned_faces(source_vertices, source_faces, vertices, faces) -> np.ndarray:
    """(F,) degrees between each output face's normal and the closest of the source normals
    within ``NEAR`` of its centre (orientation ignored; 90 where none is near)."""
    from scipy.spatial import cKDTree

    from agndc_core.labels import surface_samples

    points, normals = surface_samples(source_vertices, source_faces, NORMAL_SPACING)
    tree = cKDTree(points)
    triangles = vertices[faces]
    normal = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    length = np.linalg.norm(normal, axis=1)
    normal /= np.maximum(length, 1e-300)[:, None]
    # a plane's samples within NEAR of a point number about pi NEAR^2 / spacing^2 (44)
    _, near = tree.query(triangles.mean(axis=1), k=96, distance_upper_bound=NEAR)
    found = near < len(points)
    cosine = np.abs(np.einsum("fkd,fd->fk", normals[np.where(found, near, 0)], normal))
    best = np.where(found, cosine, 0.0).max(axis=1)
    degrees = np.degrees(np.arccos(np.clip(best, 0.0, 1.0)))
    return np.where(length > 1e-12, degrees, 0.0)  # a zero-area face has no normal


def measure_one(name, vertices, faces, resolution):
    import trimesh

    from agndc_core.meshcheck import topology_violations
    from agndc_core.pipeline import remesh_mesh

    start = time.perf_counter()
    result = remesh_mesh(vertices, faces, resolution=resolution, method="sharp")
    seconds = time.perf_counter() - start
    source = result.grid.world_to_index(vertices)
    output = result.grid.world_to_index(result.vertices)
    _, distance, _ = trimesh.proximity.closest_point(
        trimesh.Trimesh(source, faces, process=False), output)
    degrees = turned_faces(source, faces, output, result.faces)
    row = {"shape": name, "res": resolution, "vertices": len(output),
           "dist_max": distance.max(), "dist_p999": np.quantile(distance, 0.999),
           "dist_over_0.25": int(np.sum(distance > 0.25)),
           "dist_over_0.5": int(np.sum(distance > 0.5)),
           **{f"turned_{t:.0f}": int(np.sum(degrees > t)) for t in TURNED},
           "defects": sum(topology_violations(result.vertices, result.faces).values()),
           "seconds": seconds}
    return row, output, result.faces, source


def cmd_measure(args) -> None:
    folder = OUT / f"meshes_{args.res}_{args.tag}"
    folder.mkdir(parents=True, exist_ok=True)
    rows = []
    for name, vertices, faces in shapes(args.shapes):
        row, output, out_faces, source = measure_one(name, vertices, faces, args.res)
        np.savez_compressed(folder / f"{name}.npz", vertices=output, faces=out_faces,
                            source=source, source_faces=faces)
        rows.append(row)
        print("  ".join(f"{k}={v:.3f}" if isinstance(v, float) else f"{k}={v}"
                        for k, v in row.items()), flush=True)
    path = OUT / f"rows_{args.res}_{args.tag}.csv"
    with open(path, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    totals = {k: sum(r[k] for r in rows) for k in rows[0] if k.startswith(("dist_o", "turn"))}
    print(f"{len(rows)} shapes, worst vertex {max(r['dist_max'] for r in rows):.3f} voxel, "
          f"totals {totals}, defects {sum(r['defects'] for r in rows)} -> {path}")


def cmd_render(args) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from agndc_core.study.report import save_small_png

    first = OUT / f"meshes_{args.res}_{args.tags[0]}"
    names = args.shapes or sorted(p.stem for p in first.glob("*.npz"))
    for name in names:
        meshes = [np.load(OUT / f"meshes_{args.res}_{tag}" / f"{name}.npz") for tag in args.tags]
        source, source_faces = meshes[0]["source"], meshes[0]["source_faces"]
        creases = _creases(source, source_faces)
        degrees = [turned_faces(source, source_faces, m["vertices"], m["faces"]) for m in meshes]
        centres = meshes[0]["vertices"][meshes[0]["faces"]].mean(axis=1)
        places = []
        for face in np.argsort(-degrees[0]):
            if degrees[0][face] <= TURNED[0] or len(places) == args.places:
                break
            if all(np.abs(centres[face] - p).max() > 2 * args.half for p in places):
                places.append(centres[face])
        for k, place in enumerate(places):
            if args.place is not None and k != args.place:
                continue
            fig = plt.figure(figsize=(4.2 * len(VIEWS), 4.0 * len(meshes)), dpi=args.dpi)
            for row, (tag, mesh, turned) in enumerate(zip(args.tags, meshes, degrees)):
                for col, (elev, azim) in enumerate(VIEWS):
                    ax = fig.add_subplot(len(meshes), len(VIEWS), row * len(VIEWS) + col + 1,
                                         projection="3d")
                    _draw_crop(ax, mesh["vertices"], mesh["faces"], turned, creases, place,
                               args.half)
                    ax.view_init(elev=elev, azim=azim)
                    ax.set_title(f"{name} {args.res}³, {tag}: {np.sum(turned > TURNED[0])} "
                                 f"turned faces in all", fontsize=8)
            fig.subplots_adjust(left=0, right=1, bottom=0, top=0.95, wspace=0, hspace=0.08)
            png = args.out or OUT / f"{name}_{args.res}_{'_'.join(args.tags)}_{k}.png"
            save_small_png(fig, png)
            plt.close(fig)
            print(png)


#: (elevation, azimuth) of the render's columns
VIEWS = ((25, -60), (25, 40), (70, -10))


def _creases(vertices, faces, degrees: float = 20.0) -> np.ndarray:
    """(K, 2, 3) source edges whose faces meet at more than ``degrees``."""
    import trimesh

    mesh = trimesh.Trimesh(vertices, faces, process=False)
    sharp = mesh.face_adjacency_angles > np.radians(degrees)
    return vertices[mesh.face_adjacency_edges[sharp]]


def _draw_crop(ax, vertices, faces, turned, creases, centre, half) -> None:
    """The faces whose centre lies in the cube of side 2 ``half`` around ``centre``: flat-shaded,
    turned faces red, source creases black."""
    from mpl_toolkits.mplot3d.art3d import Line3DCollection, Poly3DCollection

    triangles = vertices[faces]
    keep = np.all(np.abs(triangles.mean(axis=1) - centre) < half, axis=1)
    triangles, bad = triangles[keep], turned[keep] > TURNED[0]
    normal = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True) + 1e-12
    light = np.array([0.4, -0.6, 0.7]) / np.linalg.norm([0.4, -0.6, 0.7])
    shade = 0.35 + 0.65 * np.abs(normal @ light)
    base = np.where(bad[:, None], [0.95, 0.35, 0.30], [0.78, 0.82, 0.92])
    ax.add_collection3d(Poly3DCollection(triangles, facecolors=np.clip(shade[:, None] * base,
                                                                       0, 1),
                                         linewidths=0.3, edgecolors=(0.05, 0.05, 0.15, 0.6)))
    near = np.all(np.abs(creases.mean(axis=1) - centre) < half, axis=1)
    if near.any():
        ax.add_collection3d(Line3DCollection(creases[near], colors="k", linewidths=1.2))
    for setter, c in zip((ax.set_xlim, ax.set_ylim, ax.set_zlim), centre):
        setter(c - half, c + half)
    ax.set_box_aspect((1, 1, 1))
    ax.set_axis_off()


def cmd_export(args) -> None:
    """The generated shapes (not the dev meshes) as PLY files, for ``agndc eval``."""
    import trimesh

    args.out.mkdir(parents=True, exist_ok=True)
    generated = ["bevelled_cube", "junction1", "junction2"]
    for name, vertices, faces in shapes():
        if name in generated or name.startswith("cad"):
            trimesh.Trimesh(vertices, faces, process=False).export(args.out / f"{name}.ply")
            print(args.out / f"{name}.ply")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    measure = sub.add_parser("measure")
    measure.add_argument("--res", type=int, default=64)
    measure.add_argument("--tag", default="current")
    measure.add_argument("--shapes", type=lambda s: s.split(","), default=None)
    render = sub.add_parser("render")
    render.add_argument("--res", type=int, default=64)
    render.add_argument("--tags", nargs="+", required=True)
    render.add_argument("--shapes", type=lambda s: s.split(","), default=None)
    render.add_argument("--places", type=int, default=2)
    render.add_argument("--half", type=float, default=3.0)
    render.add_argument("--dpi", type=int, default=90)
    render.add_argument("--place", type=int, default=None, help="only the K-th place")
    render.add_argument("--out", type=Path, default=None, help="the PNG (with --place)")
    export = sub.add_parser("export")
    export.add_argument("--out", type=Path, required=True)
    args = parser.parse_args(argv)
    {"measure": cmd_measure, "render": cmd_render, "export": cmd_export}[args.command](args)


if __name__ == "__main__":
    main()
