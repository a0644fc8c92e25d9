"""How flat the large planar faces of any mesh come out: the tilted-plane measure on real parts.

``research/tilted_boxes.py`` measures a rotated box, whose faces are known planes. This study
finds the planes of any mesh: its triangles joined across edges where their normals agree within
``--coplanar`` degrees, kept where the region covers at least ``--min-area`` square voxels and
none of its vertices lies more than ``--max-offset`` voxels off its plane. Each
method remeshes the mesh's grid alone (no bounding box) at ``--res``; each output triangle whose
centroid's ground-truth neighbours within ``--margin`` voxels all belong to one plane (away from
its rim, holes and creases) is that plane's. Per plane, then averaged over the planes of a class:

* **normal°**: the area-weighted mean angle between the output triangles' normals and the plane's;
* **> 2°**: the share of that area whose normals are more than 2° off (a wavy face);
* **RMS**: the RMS distance of those triangles' centroids to the plane, in voxels.

Classes by the plane's angle to its nearest grid axis: ``aligned`` (under 0.6°, the faces the
flat-patch stage places), ``tilted`` (0.6–15°: terraces, the terraced-plane fit's), ``oblique``.

    .venv/bin/python research/planar_faces.py MESH_OR_FOLDER [...] --methods mc,undc,agndc \\
        [--res 64] [--kinds cad,print]

A folder is read through its MANIFEST.csv (``agndc val-data`` or the dev meshes), ``--kinds``
choosing its rows by their ``kind`` column; ``--shapes`` by their ``shape`` column (e.g.
``tilted_part``).
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

import numpy as np

#: angle (degrees) to the nearest axis below which a plane is axis-aligned (tol.axis_aligned)
ALIGNED_DEGREES = 0.6
#: ... and below which it is slightly tilted
TILTED_DEGREES = 15.0
#: ground-truth samples per square voxel (enough for ~38 within a 2-voxel margin)
SAMPLES_PER_VOXEL2 = 3.0


def planes_of(mesh, coplanar_deg: float, min_area: float, max_offset: float = np.inf):
    """(region (F,) int, -1 off the large planes; normals (P, 3); offsets (P,)) of a trimesh:
    triangles joined across edges whose normals agree within ``coplanar_deg``, regions of at
    least ``min_area`` (the mesh's units squared) kept, each with its area-weighted plane, if
    none of its vertices lies farther than ``max_offset`` from it (a gently curved surface
    tessellated finely joins up too)."""
    import trimesh

    pairs = mesh.face_adjacency
    keep = mesh.face_adjacency_angles < np.radians(coplanar_deg)
    labels = trimesh.graph.connected_component_labels(pairs[keep], node_count=len(mesh.faces))
    weights = mesh.area_faces
    area = np.bincount(labels, weights=weights)
    # per label: the area-weighted normal and centre, and the farthest vertex from that plane
    normal = np.stack([np.bincount(labels, weights * mesh.face_normals[:, k]) for k in range(3)],
                      axis=1)
    normal /= np.maximum(np.linalg.norm(normal, axis=1), 1e-300)[:, None]
    centre = np.stack([np.bincount(labels, weights * mesh.triangles_center[:, k])
                       for k in range(3)], axis=1) / np.maximum(area, 1e-300)[:, None]
    corners = mesh.vertices[mesh.faces]  # (F, 3 corners, 3)
    reach = np.abs(np.einsum("fck,fk->fc", corners - centre[labels][:, None],
                             normal[labels])).max(axis=1)
    farthest = np.zeros(len(area))
    np.maximum.at(farthest, labels, reach)
    kept = np.flatnonzero((area >= min_area) & (farthest <= max_offset))
    index_of = np.full(len(area), -1)
    index_of[kept] = np.arange(len(kept))
    return (index_of[labels], normal[kept].reshape(-1, 3),
            np.einsum("pk,pk->p", normal[kept], centre[kept]))


def plane_class(normal: np.ndarray) -> str:
    """"aligned", "tilted" or "oblique" by the angle between ``normal`` and its nearest axis."""
    angle = np.degrees(np.arccos(np.clip(np.abs(normal).max(), 0.0, 1.0)))
    if angle < ALIGNED_DEGREES:
        return "aligned"
    return "tilted" if angle < TILTED_DEGREES else "oblique"


def flatness(vertices, faces, truth_points, truth_region, normals, offsets, voxel: float,
             margin: float) -> list[dict]:
    """Per plane with output triangles on it: {plane, normal_deg, over_2deg, rms_vx, area}.

    truth_points (S, 3) samples of the ground truth with truth_region (S,) their plane (-1 for
    none); an output triangle is plane p's when every sample within ``margin`` voxels of its
    centroid is p's (and there is one)."""
    from scipy.spatial import cKDTree

    from agndc_core.normalfilter import face_geometry

    normal, area, centre = face_geometry(np.asarray(vertices, dtype=np.float64),
                                         np.asarray(faces, dtype=np.int64))
    # every (triangle, sample) pair within the margin, gathered in C
    pairs = cKDTree(centre).sparse_distance_matrix(cKDTree(truth_points), margin * voxel,
                                                   output_type="ndarray")
    owner_of, flat = pairs["i"], truth_region[pairs["j"]]
    counts = np.bincount(owner_of, minlength=len(centre))
    lo = np.full(len(centre), np.iinfo(np.int64).max)
    hi = np.full(len(centre), np.iinfo(np.int64).min)
    np.minimum.at(lo, owner_of, flat)
    np.maximum.at(hi, owner_of, flat)
    plane = np.where((counts > 0) & (lo == hi), lo, -1)
    mine = plane >= 0
    which, weights = plane[mine], area[mine]
    cos = np.abs(np.einsum("fk,fk->f", normal[mine], normals[which]))
    angle = np.degrees(np.arccos(np.clip(cos, 0.0, 1.0)))
    distance = (np.einsum("fk,fk->f", centre[mine], normals[which]) - offsets[which]) / voxel
    n = len(normals)
    total = np.bincount(which, weights, minlength=n)
    degrees = np.bincount(which, weights * angle, minlength=n)
    over = np.bincount(which, weights * (angle > 2.0), minlength=n)
    square = np.bincount(which, weights * distance ** 2, minlength=n)
    return [{"plane": int(p), "normal_deg": float(degrees[p] / total[p]),
             "over_2deg": float(over[p] / total[p]), "rms_vx": float(np.sqrt(square[p] / total[p])),
             "area": float(total[p])}
            for p in np.flatnonzero(np.bincount(which, minlength=n))]


def meshes_of(paths, kinds, shapes) -> list[Path]:
    out = []
    for path in map(Path, paths):
        if path.is_file():
            out.append(path)
            continue
        with open(path / "MANIFEST.csv", newline="") as handle:
            for row in csv.DictReader(handle):
                if kinds and row.get("kind") not in kinds:
                    continue
                if shapes and row.get("shape", row.get("shape_id")) not in shapes:
                    continue
                out.append(path / row["file"])
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("paths", nargs="+", help="meshes, or folders with a MANIFEST.csv")
    parser.add_argument("--methods", default="mc,undc,agndc,oracle_binary")
    parser.add_argument("--res", type=int, default=64)
    parser.add_argument("--kinds", default="", help="MANIFEST kinds, comma-separated")
    parser.add_argument("--shapes", default="", help="MANIFEST shapes, comma-separated")
    parser.add_argument("--coplanar", type=float, default=1.0, help="degrees")
    parser.add_argument("--min-area", type=float, default=40.0, help="square voxels")
    parser.add_argument("--margin", type=float, default=2.0, help="voxels")
    parser.add_argument("--max-offset", type=float, default=0.02, help="voxels: how far a "
                        "plane's vertices may lie from it")
    parser.add_argument("--per-mesh", action="store_true")
    args = parser.parse_args()

    import trimesh

    from agndc_core.gridio import load_mesh
    from agndc_core.pipeline import remesh_mesh
    from agndc_core.voxelize import checked_surface, grid_layout

    kinds = [k for k in args.kinds.split(",") if k]
    shapes = [s for s in args.shapes.split(",") if s]
    methods = args.methods.split(",")
    classes = ("aligned", "tilted", "oblique")
    table = {(m, c): [] for m in methods for c in classes}  # plane rows of every mesh
    for path in meshes_of(args.paths, kinds, shapes):
        vertices, faces = load_mesh(path)
        truth = trimesh.Trimesh(vertices, faces, process=False)
        used = checked_surface(vertices, faces)[2]  # voxelize's extent, and so its voxel
        voxel = grid_layout(np.ptp(used, axis=0), args.res)[0]
        region, normals, offsets = planes_of(truth, args.coplanar, args.min_area * voxel ** 2,
                                             args.max_offset * voxel)
        count = int(SAMPLES_PER_VOXEL2 * truth.area / voxel ** 2)
        points, index = trimesh.sample.sample_surface(truth, count, seed=0)
        kind_of = [plane_class(n) for n in normals]
        for method in methods:
            result = remesh_mesh(vertices, faces, resolution=args.res, method=method,
                                 source="planar_faces", source_bounds=False)
            rows = flatness(result.vertices, result.faces, points, region[index], normals,
                            offsets, voxel, args.margin)
            for row in rows:
                table[method, kind_of[row["plane"]]].append(row)
            if args.per_mesh:
                line = f"{path.stem:22s} {method:14s}"
                for c in classes:
                    mine = [r for r in rows if kind_of[r["plane"]] == c]
                    if mine:
                        degrees = np.mean([r["normal_deg"] for r in mine])
                        line += (f" {c} {len(mine)}: {degrees:.2f}°"
                                 f" {np.mean([r['over_2deg'] for r in mine]):.0%}"
                                 f" {np.mean([r['rms_vx'] for r in mine]):.3f}")
                print(line, flush=True)
    print(f"\nplanes of at least {args.min_area:g} voxels², {args.margin:g}-voxel margin, "
          f"{args.res}³, grid alone; mean over planes: normal° / share of area over 2° / RMS vx")
    print("| method | " + " | ".join(classes) + " |")
    print("|---|" + "---|" * len(classes))
    for method in methods:
        cells = []
        for c in classes:
            rows = table[method, c]
            cells.append("–" if not rows else
                         f"{np.mean([r['normal_deg'] for r in rows]):.2f}° / "
                         f"{np.mean([r['over_2deg'] for r in rows]):.0%} / "
                         f"{np.mean([r['rms_vx'] for r in rows]):.3f} ({len(rows)})")
        print(f"| {method} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
