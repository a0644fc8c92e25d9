"""How flat the faces of a slightly rotated box come out: the tilted-plane measurement.

A box (1 x 0.8 x 0.5) rotated by an angle about an oblique axis, so that every face is tilted
off its axis, is voxelised and remeshed by each method. The output faces are assigned to the
box face whose plane is nearest; faces within ``--margin`` voxels of another box face (the
creases and their bevels) are left out. Per box face and then averaged over the six:

* **normal deviation**: the area-weighted mean angle between the output faces' normals and the
  true face normal, in degrees (a wavy face tilts its triangles every way);
* **RMS to the plane**: the RMS distance of the kept faces' vertices to the true plane, in
  voxels (flatness and placement together);
* **RMS to its own plane**: the RMS about the vertices' own least-squares plane (flatness alone).

    .venv/bin/python research/tilted_boxes.py --angles 1 2.5 5 10 --res 64 \\
        --methods mc surfacenets undc agndc agndc_fast oracle_binary
    .venv/bin/python research/tilted_boxes.py --methods agndc new=agndc \\
        --checkpoint new=runs/RUN/step-000800.safetensors
    .venv/bin/python research/tilted_boxes.py --figure docs/images/tilted_box_1deg.png

``--figure`` draws the box tilted 1° at 128³ by AGNDC without and with the terraced planes'
projections into their layers (``flatpatches._into_layers``), flat-shaded.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

BOX = np.array([1.0, 0.8, 0.5])
#: the rotation axis: oblique, so that the rotation tilts all three face pairs
AXIS = np.array([1.0, 0.6, 0.35])


def rotation(angle_deg: float, axis=AXIS) -> np.ndarray:
    """(3, 3) rotation by ``angle_deg`` about ``axis`` (Rodrigues)."""
    k = np.asarray(axis, dtype=np.float64)
    k = k / np.linalg.norm(k)
    a = np.radians(angle_deg)
    cross = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(a) * cross + (1 - np.cos(a)) * cross @ cross


def box_mesh(angle_deg: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(vertices, faces, rotation) of the rotated box, centred at the origin."""
    import trimesh

    box = trimesh.creation.box(BOX)
    turn = rotation(angle_deg)
    return np.asarray(box.vertices) @ turn.T, np.asarray(box.faces), turn


def face_flatness(vertices, faces, turn, voxel: float, margin_vx: float) -> dict:
    """The measurements of the module docstring for one remeshed box (world units in,
    degrees and voxels out)."""
    half = BOX / 2
    local = vertices @ turn  # the box's own frame: its faces are the planes |x_i| = half_i
    corners = local[faces]  # (F, 3, 3)
    centroid = corners.mean(axis=1)
    cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    area = 0.5 * np.linalg.norm(cross, axis=1)
    normal = cross / np.maximum(2 * area, 1e-30)[:, None]
    # the nearest box plane of each face: axis and side
    gap = half[None, :] - np.abs(centroid)  # (F, 3) distance inwards from each face pair
    axis = np.argmin(np.abs(gap), axis=1)
    side = np.sign(centroid[np.arange(len(faces)), axis])
    margin = margin_vx * voxel
    other = np.ones((len(faces), 3), dtype=bool)
    other[np.arange(len(faces)), axis] = False
    # away from the creases: every other face pair at least ``margin`` away
    inner = np.all(np.where(other, gap >= margin, True), axis=1)
    rows = []
    for a in range(3):
        for s in (-1.0, 1.0):
            kept = inner & (axis == a) & (side == s) & (area > 0)
            if kept.sum() < 3:
                continue
            true_normal = np.zeros(3)
            true_normal[a] = s
            cosine = np.clip(normal[kept] @ true_normal, -1.0, 1.0)
            deviation = np.degrees(np.arccos(cosine))
            used = np.unique(faces[kept])
            height = local[used, a] * s - half[a]  # signed distance to the true plane
            points = local[used]
            design = np.c_[np.delete(points, a, axis=1), np.ones(len(points))]
            fit = np.linalg.lstsq(design, points[:, a], rcond=None)[0]
            own = points[:, a] - design @ fit
            rows.append((np.average(deviation, weights=area[kept]),
                         np.sqrt(np.mean(height ** 2)) / voxel,
                         np.sqrt(np.mean(own ** 2)) / voxel))
    rows = np.array(rows)
    return {"faces_measured": len(rows), "normal_deg": float(rows[:, 0].mean()),
            "rms_plane_vx": float(rows[:, 1].mean()), "rms_own_vx": float(rows[:, 2].mean()),
            "worst_normal_deg": float(rows[:, 0].max()), "worst_rms_vx": float(rows[:, 1].max())}


def draw_projections(path: str, angle: float = 1.0, res: int = 128) -> None:
    """The picture of ``--figure`` (module docstring)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from agndc_core import pipeline
    from agndc_core.study.report import _draw, save_small_png
    from agndc_core.tolerances import tol

    vertices, faces, _ = box_mesh(angle)
    passes = tol.terrace_projections
    fig = plt.figure(figsize=(8.0, 4.2), dpi=90)
    try:
        for col, (title, projections) in enumerate((("without the projections", 0),
                                                    ("with the projections", passes))):
            tol.terrace_projections = projections
            result = pipeline.remesh_mesh(vertices, faces, resolution=res)
            ax = fig.add_subplot(1, 2, col + 1, projection="3d")
            _draw(ax, result.vertices, result.faces, vertices)
            ax.view_init(elev=55, azim=-70)
            ax.set_title(f"AGNDC, box tilted {angle:g}° at {res}³, {title}", fontsize=8)
    finally:
        tol.terrace_projections = passes
    fig.subplots_adjust(left=0, right=1, bottom=0, top=0.92, wspace=0)
    save_small_png(fig, path)
    print(path)


def main() -> None:
    from agndc_core import pipeline

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--angles", type=float, nargs="+", default=[1.0, 2.5, 5.0, 10.0])
    parser.add_argument("--res", type=int, nargs="+", default=[64])
    parser.add_argument("--methods", nargs="+",
                        default=["mc", "surfacenets", "undc", "agndc", "oracle_binary"])
    parser.add_argument("--margin", type=float, default=3.0,
                        help="voxels kept clear of the box's other faces (its creases)")
    parser.add_argument("--threads", type=int, default=0)
    parser.add_argument("--checkpoint", action="append", default=[], metavar="LABEL=PATH",
                        help="weights of a LABEL=METHOD entry of --methods (as agndc eval)")
    parser.add_argument("--figure", help="draw the picture of the 1° box to this PNG instead")
    args = parser.parse_args()
    if args.figure:
        draw_projections(args.figure)
        return
    from agndc_core.study.evaluate import method_checkpoint, method_parts, parse_methods

    methods = parse_methods(",".join(args.methods))
    checkpoints = dict(item.split("=", 1) for item in args.checkpoint)
    print(f"load average {os.getloadavg()[0]:.2f}")
    print("res  angle  method          normal°  worst°  RMS plane  worst  RMS own   s")
    for res in args.res:
        for angle in args.angles:
            vertices, faces, turn = box_mesh(angle)
            for entry in methods:
                label, method, _ = method_parts(entry)
                start = time.perf_counter()
                result = pipeline.remesh_mesh(
                    vertices, faces, resolution=res, method=method, threads=args.threads,
                    checkpoint=method_checkpoint(checkpoints, label, method))
                seconds = time.perf_counter() - start
                voxel = float(np.abs(result.grid.voxel_size).max())
                m = face_flatness(result.vertices, result.faces, turn, voxel, args.margin)
                print(f"{res:3d}  {angle:5.1f}  {label:14s} {m['normal_deg']:7.2f} "
                      f"{m['worst_normal_deg']:7.2f}  {m['rms_plane_vx']:9.3f} "
                      f"{m['worst_rms_vx']:6.3f}  {m['rms_own_vx']:7.3f} {seconds:5.1f}",
                      flush=True)


if __name__ == "__main__":
    main()
