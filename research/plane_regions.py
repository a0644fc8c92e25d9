"""Planar regions of the filtered mesh put on one plane: region growing on the face normals and
a plane fit, creases kept.

The terraced-plane fit (``flatpatches.fit_terraced_planes``) flattens a slightly tilted face
that crosses three or more layers; a face crossing fewer, or one tilted beyond ~15°, keeps the
network's vertices and the normal filter's smoothing, and comes out with its triangles 2–3° off
the plane (``research/planar_faces.py``). This study adds a stage after the normal filter:

1. faces joined across shared edges where their normals agree within ``--join`` degrees;
2. each region of at least ``--min-faces`` faces fitted with a least-squares plane (its
   vertices, area-weighted); faces more than ``--keep`` degrees off it or ``--band`` voxels
   away are dropped and the rest joined and fitted again;
3. a region is kept when its vertices lie within ``--rms`` voxels RMS of its plane and the
   plane is not axis-aligned (the flat-patch stage has those); ``--max-tilt`` keeps only
   planes within that many degrees of an axis;
4. every vertex whose faces all belong to one kept region is projected onto its plane (the rim,
   the creases and the pinned coordinates stay).

    .venv/bin/python research/plane_regions.py DATA -o OUT --cache DIR [--res 64] [--shifts 3]
"""

from __future__ import annotations

import numpy as np
from stage_eval import eval_parser, run_eval_cached

#: a plane within this many degrees of an axis is the flat-patch stage's
ALIGNED_DEGREES = 0.6


def edge_pairs(faces: np.ndarray) -> np.ndarray:
    """(E, 2) pairs of faces sharing an edge (a closed 2-manifold: two per edge)."""
    edges = np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    owner = np.repeat(np.arange(len(faces)), 3)
    order = np.lexsort((edges[:, 1], edges[:, 0]))
    edges, owner = edges[order], owner[order]
    same = np.all(edges[1:] == edges[:-1], axis=1)
    return np.stack([owner[:-1][same], owner[1:][same]], axis=1)


def components(n: int, pairs: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """(n,) component label of each node over the kept ``pairs``."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components

    chosen = pairs[keep]
    graph = sp.coo_matrix((np.ones(len(chosen)), (chosen[:, 0], chosen[:, 1])), shape=(n, n))
    return connected_components(graph, directed=False)[1]


def fit_planes(vertices, faces, label, areas, min_faces: int):
    """Least-squares planes (the faces' corners, weighted by the face areas) of the labels with
    at least ``min_faces`` faces: (labels kept (R,), unit normals (R, 3), offsets (R,))."""
    big = np.flatnonzero(np.bincount(label) >= min_faces)
    plane_of = np.full(label.max() + 1, -1)
    plane_of[big] = np.arange(len(big))
    mine = plane_of[label] >= 0
    which = np.repeat(plane_of[label][mine], 3)  # a plane per corner
    corners = vertices[faces[mine]].reshape(-1, 3)
    weights = np.repeat(areas[mine], 3)
    total = np.bincount(which, weights, minlength=len(big))
    centre = np.stack([np.bincount(which, weights * corners[:, k], minlength=len(big))
                       for k in range(3)], axis=1) / total[:, None]
    # the weighted scatter about each region's own centre (two passes: no cancellation)
    spread = corners - centre[which]
    scatter = np.zeros((len(big), 3, 3))
    np.add.at(scatter, which, weights[:, None, None] * spread[:, :, None] * spread[:, None, :])
    normals = np.linalg.eigh(scatter)[1][:, :, 0]  # the direction of least spread
    return big, normals, np.einsum("rk,rk->r", normals, centre)


def snap_planar_regions(vertices, faces, fixed=None, *, join=4.0, keep=6.0, band=0.3,
                        min_faces=40, rms=0.08, max_tilt=90.0, rounds=2) -> np.ndarray:
    """(V, 3) vertices (lattice units) with the interior vertices of planar regions on their
    plane; ``fixed`` (V, 3) bool, coordinates that must not move (their vertices stay)."""
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    from agndc_core.normalfilter import face_geometry

    normal, areas, face_centre = face_geometry(vertices, faces)
    pairs = edge_pairs(faces)
    cos_join = np.cos(np.radians(join))
    label = components(len(faces), pairs, np.einsum("ij,ij->i", normal[pairs[:, 0]],
                                                    normal[pairs[:, 1]]) > cos_join)
    for _ in range(rounds):
        big, normals, offsets = fit_planes(vertices, faces, label, areas, min_faces)
        plane_of = np.full(label.max() + 1, -1)
        plane_of[big] = np.arange(len(big))
        plane = plane_of[label]
        inside = plane >= 0
        off_angle = np.abs(np.einsum("ij,ij->i", normal[inside], normals[plane[inside]]))
        off_band = np.abs(np.einsum("ij,ij->i", face_centre[inside], normals[plane[inside]])
                          - offsets[plane[inside]])
        member = np.zeros(len(faces), dtype=bool)
        member[inside] = (off_angle > np.cos(np.radians(keep))) & (off_band <= band)
        joined = member[pairs[:, 0]] & member[pairs[:, 1]] \
            & (label[pairs[:, 0]] == label[pairs[:, 1]])
        label = components(len(faces), pairs, joined)  # a dropped face is a region of one
    big, normals, offsets = fit_planes(vertices, faces, label, areas, min_faces)
    out = vertices.copy()
    if len(big) == 0:
        return out
    plane_of = np.full(label.max() + 1, -1)
    plane_of[big] = np.arange(len(big))
    face_plane = plane_of[label]
    # a vertex's faces all on one plane: the smallest and the largest plane index agree
    lo = np.full(len(vertices), np.iinfo(np.int64).max)
    hi = np.full(len(vertices), -2)
    for corner in range(3):
        np.minimum.at(lo, faces[:, corner], face_plane)
        np.maximum.at(hi, faces[:, corner], face_plane)
    interior = (lo == hi) & (lo >= 0)
    if fixed is not None:
        interior &= ~np.asarray(fixed).any(axis=1)
    tilt = np.degrees(np.arccos(np.clip(np.abs(normals).max(axis=1), 0.0, 1.0)))
    good = (tilt >= ALIGNED_DEGREES) & (tilt <= max_tilt)
    on_plane = face_plane >= 0
    which = np.repeat(face_plane[on_plane], 3)
    corners = vertices[faces[on_plane]].reshape(-1, 3)
    distance = np.einsum("ck,ck->c", corners, normals[which]) - offsets[which]
    square = np.bincount(which, distance ** 2, minlength=len(big))
    good &= np.sqrt(square / np.bincount(which, minlength=len(big))) <= rms
    moving = interior & good[np.maximum(lo, 0)]
    which = lo[moving]
    distance = np.einsum("ij,ij->i", out[moving], normals[which]) - offsets[which]
    out[moving] -= distance[:, None] * normals[which]
    return out


def main() -> None:
    parser = eval_parser(__doc__, cache=True)
    parser.add_argument("--join", type=float, default=4.0, help="degrees between neighbours")
    parser.add_argument("--keep", type=float, default=6.0, help="degrees off the region's plane")
    parser.add_argument("--band", type=float, default=0.3, help="voxels off the region's plane")
    parser.add_argument("--min-faces", type=int, default=40, help="faces of a region")
    parser.add_argument("--rms", type=float, default=0.08, help="voxels RMS about the plane")
    parser.add_argument("--max-tilt", type=float, default=90.0, help="degrees off an axis")
    args = parser.parse_args()

    from agndc_core import pipeline

    filtered = pipeline.filter_contoured_mesh

    def filter_and_snap(vertices, faces, vertex, pinned, check=None):
        from agndc_core.flatpatches import pinned_coordinates

        out = filtered(vertices, faces, vertex, pinned, check=check)
        fixed = pinned_coordinates(vertices, vertex, pinned)
        return snap_planar_regions(out, faces, fixed, join=args.join, keep=args.keep,
                                   band=args.band, min_faces=args.min_faces, rms=args.rms,
                                   max_tilt=args.max_tilt)

    pipeline.filter_contoured_mesh = filter_and_snap  # the pipeline looks it up at each call
    run_eval_cached(args)


if __name__ == "__main__":
    main()
