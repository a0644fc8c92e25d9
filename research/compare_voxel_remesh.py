"""AGNDC's sharp mode against Blender's own Remesh modifier (Voxel and Sharp octree modes).

    .venv-bpy/bin/python research/compare_voxel_remesh.py measure --res 64 [--kinds cad,organic]
    .venv-bpy/bin/python research/compare_voxel_remesh.py timing --res 64 128 256 \
        --meshes fandisk,bunny --repeat 3
    .venv-bpy/bin/python research/compare_voxel_remesh.py meshes --res 64   # fandisk, bevelled cube
    .venv/bin/python research/compare_voxel_remesh.py render --res 64     # matplotlib (core venv)
    .venv/bin/python research/compare_voxel_remesh.py tables              # markdown for the doc

Every method sees the **same voxel size** ``h = longest bounding-box side / (res - 2)``: that is
``agndc_core.voxelize.voxelize``'s convention (``resolution`` voxels along the longest side, one
empty margin voxel on each end, so ``res - 2`` voxel spacings span the shape). Blender's methods:

* ``voxel``: the Remesh modifier, ``mode='VOXEL'``, ``voxel_size = h``, adaptivity 0 (OpenVDB);
* ``octree_sharp``: the Remesh modifier, ``mode='SHARP'`` (octree dual contouring), depth
  ``d = ceil(log2(res - 2))`` and ``scale = (res - 2) / 2**d``: its cells are
  ``longest side / (scale * 2**d) = h`` (measured with BLOCKS mode: the cell size is exactly
  that for scale <= 0.99; Blender clamps larger scales to 0.99, so 256³ is 0.2 % coarser);
  ``use_remove_disconnected`` off, so no real part of a multi-body mesh is dropped.

AGNDC's methods run ``agndc_core.pipeline.remesh_mesh`` (``agndc``, ``mc``, ``sharp``); their
time includes voxelisation (and, for sharp, the exact intersections). Blender's time is the
depsgraph evaluation of the modifier plus ``to_mesh`` (the source object already exists). Every
output is triangulated, scored with ``agndc_core.metrics.evaluate`` against the source
(CD, F1, NC, ECD, EF1 in the source's normalised frame) and checked with
``agndc_core.meshcheck.topology_violations``. Results go to ``--out`` (default
``out/voxel_compare``): ``rows_<res>.csv``, ``timing.csv``, ``meshes_<res>/*.npz`` and PNGs.
"""

from __future__ import annotations

import argparse
import csv
import math
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # a script: the checkout's agndc_core, installed or not

DATA = ROOT.parent / "shared" / "data" / "dev"
OUT = ROOT / "out" / "voxel_compare"
#: AGNDC's methods (agndc_core.pipeline) and Blender's (Remesh modifier modes)
CORE_METHODS = ("agndc", "mc", "sharp")
BLENDER_METHODS = ("voxel", "octree_sharp")
METHODS = CORE_METHODS + BLENDER_METHODS
LABELS = {"source": "source", "agndc": "AGNDC", "mc": "MC", "sharp": "AGNDC sharp",
          "voxel": "Blender Voxel", "octree_sharp": "Blender Sharp (octree)"}
METRICS = ("cd", "f1", "nc", "ecd", "ef1")
#: Blender clamps the Remesh modifier's octree scale to this (measured, see module docstring)
OCTREE_MAX_SCALE = 0.99
BEVELLED_CUBE = "bevelled_cube"


def voxel_size(vertices: np.ndarray, resolution: int) -> float:
    """``voxelize``'s voxel size: longest bounding-box side / (resolution - 2 margin voxels)."""
    return float((vertices.max(0) - vertices.min(0)).max()) / (resolution - 2)


def octree_settings(resolution: int) -> tuple[int, float]:
    """(depth, scale) of Blender's octree remesh whose cell is ``voxel_size(., resolution)``."""
    depth = math.ceil(math.log2(resolution - 2))
    return depth, min((resolution - 2) / 2**depth, OCTREE_MAX_SCALE)


# -- inputs ----------------------------------------------------------------------------------

def dev_meshes(kinds: list[str]) -> list[tuple[str, str, Path]]:
    """(name, kind, path) of the dev meshes of the given MANIFEST.csv kinds."""
    with open(DATA / "MANIFEST.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    return [(Path(r["file"]).stem, r["kind"], DATA / r["file"]) for r in rows
            if r["kind"] in kinds and (DATA / r["file"]).exists()]


def load_named(name: str, kinds=("cad", "organic", "print (Thingi10K)")):
    """(vertices, faces, kind) of a dev mesh by file stem, or the bevelled cube."""
    from agndc_core.gridio import load_mesh

    if name == BEVELLED_CUBE:
        return (*bevelled_cube(), "synthetic")
    for stem, kind, path in dev_meshes(list(kinds)):
        if stem == name or path.name == name:
            return (*load_mesh(path), kind)
    raise SystemExit(f"no dev mesh named {name!r} in {DATA / 'MANIFEST.csv'}")


def bevelled_cube():
    """A 2-unit cube with Blender's Bevel modifier applied (width 0.25, 3 segments), rotated
    off the axes (so neither method sees its faces aligned with the grid); triangulated."""
    bpy = _bpy()
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.mesh.primitive_cube_add(size=2.0)
    obj = bpy.context.object
    bevel = obj.modifiers.new("bevel", "BEVEL")
    bevel.width, bevel.segments, bevel.limit_method = 0.25, 3, "NONE"
    obj.rotation_euler = (math.radians(20), math.radians(-15), math.radians(35))
    vertices, faces = evaluated_triangles(obj)
    rotation = np.array(obj.matrix_world.to_3x3())
    return vertices @ rotation.T, faces


# -- Blender ---------------------------------------------------------------------------------

def _bpy():
    os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="agndc_cmp_"))
    import bpy

    return bpy


def mesh_object(vertices: np.ndarray, faces: np.ndarray, name: str = "source"):
    """A new object holding the triangle mesh, built in bulk with ``foreach_set``."""
    bpy = _bpy()
    mesh = bpy.data.meshes.new(name)
    mesh.vertices.add(len(vertices))
    mesh.vertices.foreach_set("co", np.ascontiguousarray(vertices, np.float32).reshape(-1))
    mesh.loops.add(faces.size)
    mesh.loops.foreach_set("vertex_index", np.ascontiguousarray(faces, np.int32).reshape(-1))
    mesh.polygons.add(len(faces))
    mesh.polygons.foreach_set("loop_start", np.arange(0, faces.size, 3, dtype=np.int32))
    mesh.update(calc_edges=True)
    obj = bpy.data.objects.new(name, mesh)
    bpy.context.scene.collection.objects.link(obj)
    return obj


def evaluated_triangles(obj) -> tuple[np.ndarray, np.ndarray]:
    """(V, 3) float64 vertices and (T, 3) int64 triangles of the object's evaluated mesh."""
    bpy = _bpy()
    evaluated = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
    mesh = evaluated.to_mesh()
    try:
        return _mesh_arrays(mesh)
    finally:
        evaluated.to_mesh_clear()


def _mesh_arrays(mesh) -> tuple[np.ndarray, np.ndarray]:
    mesh.calc_loop_triangles()
    co = np.zeros(len(mesh.vertices) * 3, np.float32)
    mesh.vertices.foreach_get("co", co)
    tris = np.zeros(len(mesh.loop_triangles) * 3, np.int32)
    mesh.loop_triangles.foreach_get("vertices", tris)
    return co.reshape(-1, 3).astype(np.float64), tris.reshape(-1, 3).astype(np.int64)


def blender_remesh(obj, method: str, resolution: int, h: float):
    """Blender's Remesh modifier on ``obj``: (vertices, triangles, seconds)."""
    bpy = _bpy()
    modifier = obj.modifiers.new("remesh", "REMESH")
    if method == "voxel":
        modifier.mode, modifier.voxel_size, modifier.adaptivity = "VOXEL", h, 0.0
    else:
        depth, scale = octree_settings(resolution)
        modifier.mode, modifier.octree_depth, modifier.scale = "SHARP", depth, scale
        modifier.use_remove_disconnected = False
    try:
        start = time.perf_counter()
        evaluated = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
        mesh = evaluated.to_mesh()
        seconds = time.perf_counter() - start
        vertices, faces = _mesh_arrays(mesh)
        evaluated.to_mesh_clear()
    finally:
        obj.modifiers.remove(modifier)
    return vertices, faces, seconds


def run_method(method: str, vertices, faces, resolution: int, obj, threads: int):
    """(vertices, faces, seconds) of one method at one resolution."""
    if method in BLENDER_METHODS:
        return blender_remesh(obj, method, resolution, voxel_size(vertices, resolution))
    from agndc_core.pipeline import remesh_mesh

    start = time.perf_counter()
    result = remesh_mesh(vertices, faces, resolution=resolution, method=method, threads=threads)
    return result.vertices, result.faces, time.perf_counter() - start


def score(pred_v, pred_f, vertices, faces) -> dict:
    """Metrics (raw units) and manifold defects of one output."""
    from agndc_core.meshcheck import topology_violations
    from agndc_core.metrics import evaluate

    metrics = evaluate(pred_v, pred_f, vertices, faces)
    defects = topology_violations(pred_v, pred_f)
    return {**{k: metrics[k] for k in METRICS}, **defects,
            "manifold": int(all(v == 0 for k, v in defects.items() if k != "unused_vertices")),
            "components": n_components(pred_f, len(pred_v))}


def n_components(faces: np.ndarray, n_vertices: int) -> int:
    """Connected components (by shared vertices) of the faces."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    if len(faces) == 0:
        return 0
    a, b = np.concatenate([faces[:, :2], faces[:, 1:]]).T
    graph = coo_matrix((np.ones(len(a)), (a, b)), shape=(n_vertices, n_vertices))
    used = np.unique(faces)
    _, label = connected_components(graph, directed=False)
    return len(np.unique(label[used]))


# -- commands --------------------------------------------------------------------------------

def cmd_measure(args) -> None:
    """Quality rows for every mesh x method at each resolution (appends, skips done rows)."""
    bpy = _bpy()
    names = [(n, k, p) for n, k, p in dev_meshes(args.kinds.split(","))]
    if args.bevelled_cube:
        names.append((BEVELLED_CUBE, "synthetic", None))
    if args.limit:
        names = names[: args.limit]
    _warm_up(args.threads)
    for resolution in args.res:
        path = args.out / f"rows_{resolution}.csv"
        done = {(r["name"], r["method"]) for r in read_rows(path)}
        for name, kind, _ in names:
            if all((name, m) in done for m in args.methods):
                continue
            vertices, faces, _ = load_named(name)
            bpy.ops.wm.read_homefile(use_empty=True)
            obj = mesh_object(vertices, faces)
            for method in args.methods:
                if (name, method) in done:
                    continue
                row = {"name": name, "kind": kind, "method": method, "res": resolution,
                       "source_faces": len(faces)}
                try:
                    pv, pf, seconds = run_method(method, vertices, faces, resolution, obj,
                                                 args.threads)
                    row.update(faces=len(pf), seconds=round(seconds, 4),
                               **score(pv, pf, vertices, faces), error="")
                except Exception as exc:  # noqa: BLE001 - a failure is a result row
                    row.update(error=f"{type(exc).__name__}: {exc}")
                append_row(path, row)
                print(f"{resolution} {name:24s} {method:13s} "
                      f"{row.get('seconds', '-')} s  cd {row.get('cd', '-')}  "
                      f"ef1 {row.get('ef1', '-')}  manifold {row.get('manifold', '-')}",
                      flush=True)


def _warm_up(threads: int) -> None:
    """Load the shipped network once, so no row's time includes reading the weights."""
    import trimesh

    from agndc_core.pipeline import remesh_mesh

    box = trimesh.creation.box((1.0, 1.0, 1.0))
    remesh_mesh(box.vertices, box.faces, resolution=16, method="agndc", threads=threads)


def cmd_timing(args) -> None:
    """Wall time (min and median of --repeat) per mesh x method x resolution; each method is
    run once first at the lowest resolution (loads the network, warms the caches)."""
    bpy = _bpy()
    path = args.out / "timing.csv"
    for name in args.meshes.split(","):
        vertices, faces, kind = load_named(name)
        bpy.ops.wm.read_homefile(use_empty=True)
        obj = mesh_object(vertices, faces)
        for method in args.methods:
            run_method(method, vertices, faces, min(args.res), obj, args.threads)  # warm-up
            for resolution in args.res:
                times = []
                for _ in range(args.repeat):
                    pv, pf, seconds = run_method(method, vertices, faces, resolution, obj,
                                                 args.threads)
                    times.append(seconds)
                row = {"name": name, "kind": kind, "method": method, "res": resolution,
                       "faces": len(pf), "min_s": round(min(times), 4),
                       "median_s": round(float(np.median(times)), 4), "repeat": args.repeat,
                       "threads": args.threads, "load1": round(os.getloadavg()[0], 2)}
                append_row(path, row)
                print(row, flush=True)


def cmd_meshes(args) -> None:
    """Save the source and every method's output of the picture shapes (npz) for ``render``."""
    bpy = _bpy()
    folder = args.out / f"meshes_{args.res[0]}"
    folder.mkdir(parents=True, exist_ok=True)
    for name in args.meshes.split(","):
        vertices, faces, _ = load_named(name)
        bpy.ops.wm.read_homefile(use_empty=True)
        obj = mesh_object(vertices, faces)
        np.savez_compressed(folder / f"{name}_source.npz", vertices=vertices, faces=faces)
        for method in args.methods:
            pv, pf, _ = run_method(method, vertices, faces, args.res[0], obj, args.threads)
            np.savez_compressed(folder / f"{name}_{method}.npz", vertices=pv, faces=pf)
            print(f"{name} {method}: {len(pf)} faces", flush=True)


def cmd_render(args) -> None:
    """One PNG per picture shape, 2 x 3 panels: source, AGNDC, MC / sharp, Voxel, octree Sharp."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    folder = args.out / f"meshes_{args.res[0]}"
    columns = ["source", *args.methods]
    n_rows = math.ceil(len(columns) / 3)
    for name in args.meshes.split(","):
        meshes = {c: np.load(folder / f"{name}_{c}.npz") for c in columns}
        reference = meshes["source"]["vertices"]
        fig = plt.figure(figsize=(4.4 * 3, 4.0 * n_rows), dpi=args.dpi)
        for index, column in enumerate(columns):
            ax = fig.add_subplot(n_rows, 3, index + 1, projection="3d")
            v, f = meshes[column]["vertices"], meshes[column]["faces"]
            draw_mesh(ax, v, f, reference, elev=args.elev, azim=args.azim, zoom=args.zoom)
            ax.set_title(f"{LABELS[column]} ({len(f):,} triangles)", fontsize=11, y=0.97)
        fig.subplots_adjust(left=0, right=1, bottom=0, top=0.97, wspace=0, hspace=0.02)
        suffix = f"_{args.tag}" if args.tag else ""
        png = args.images / f"voxel_compare_{name}_{args.res[0]}{suffix}.png"
        fig.savefig(png)
        plt.close(fig)
        _quantize(png)
        print(f"{png}  {png.stat().st_size / 1e3:.0f} KB")


def draw_mesh(ax, vertices, faces, reference, *, elev, azim, zoom=1.0) -> None:
    """Flat-shaded triangles (two-sided head light) with thin dark edges, framed on the source
    mesh's bounding box (same frame in every panel; ``zoom`` > 1 shows the middle part)."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    tri = vertices[faces]  # (F, 3, 3)
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True) + 1e-12
    light = np.array([0.4, -0.6, 0.7]) / np.linalg.norm([0.4, -0.6, 0.7])
    shade = 0.3 + 0.7 * np.abs(normal @ light)  # (F,)
    colors = np.clip(shade[:, None] * np.array([0.78, 0.82, 0.92]), 0, 1)
    width = float(np.clip(25.0 / np.sqrt(max(len(faces), 1)), 0.08, 0.6))
    ax.add_collection3d(Poly3DCollection(tri, facecolors=colors, linewidths=width,
                                         edgecolors=(0.05, 0.05, 0.15, 0.55)))
    lo, hi = reference.min(0), reference.max(0)
    centre, half = (lo + hi) / 2, (hi - lo).max() / 2 / zoom
    for setter, c in zip((ax.set_xlim, ax.set_ylim, ax.set_zlim), centre):
        setter(c - half, c + half)
    ax.set_box_aspect((1, 1, 1), zoom=1.25)
    ax.view_init(elev=elev, azim=azim)
    ax.set_axis_off()


def _quantize(png: Path) -> None:
    """Palette PNG (64 colours): the flat-shaded renders lose nothing visible, size drops ~3x."""
    from PIL import Image

    Image.open(png).convert("RGB").quantize(64).save(png, optimize=True)


def cmd_tables(args) -> None:
    """Markdown: per-kind means at each resolution, manifold counts, timings."""
    for resolution in args.res:
        rows = [r for r in read_rows(args.out / f"rows_{resolution}.csv") if not r["error"]]
        print(f"\n### {resolution}³\n")
        print(quality_table(rows, args.methods))
        print(f"\n#### defects at {resolution}³ (sums over the meshes)\n")
        print(defect_table(rows, args.methods))
        print(f"\n#### per mesh at {resolution}³: CD×10⁵ / EF1 (✗: not 2-manifold)\n")
        print(per_mesh_table(rows, args.methods))
    timing = read_rows(args.out / "timing.csv")
    if timing:
        print("\n### timing\n")
        print(timing_table(timing, args.methods))


def quality_table(rows, methods) -> str:
    """Means per (kind, method): CD×10⁵, F1, NC, ECD×10², EF1, faces, seconds, manifold."""
    head = ("kind | method | shapes | CD×10⁵ ↓ | F1 ↑ | NC ↑ | ECD×10² ↓ | EF1 ↑ | "
            "triangles | time s | manifold | non-manifold edges (mean)")
    lines = [f"| {head} |", "|" + "---|" * (head.count("|") + 1)]
    order = ["cad", "organic", "print (Thingi10K)", "synthetic"]
    kinds = sorted({r["kind"] for r in rows}, key=lambda k: (k not in order, order.index(k)
                                                               if k in order else 0, k))
    for kind in kinds:
        for method in methods:
            mine = [r for r in rows if r["kind"] == kind and r["method"] == method]
            if not mine:
                continue
            mean = {k: _nanmean([float(r[k]) for r in mine]) for k in
                    (*METRICS, "faces", "seconds", "edges_not_in_two_faces")}
            manifold = sum(int(r["manifold"]) for r in mine)
            cells = [_fmt(mean["cd"] * 1e5, 2), _fmt(mean["f1"], 3), _fmt(mean["nc"], 3),
                     _fmt(mean["ecd"] * 1e2, 3), _fmt(mean["ef1"], 3)]
            lines.append(
                f"| {kind} | {LABELS[method]} | {len(mine)} | {' | '.join(cells)} | "
                f"{mean['faces']:,.0f} | {mean['seconds']:.2f} | "
                f"{manifold}/{len(mine)} | {mean['edges_not_in_two_faces']:.1f} |")
    return "\n".join(lines)


DEFECTS = ("edges_not_in_two_faces", "edges_same_direction_twice", "vertices_not_one_fan",
           "degenerate_faces")


def defect_table(rows, methods) -> str:
    """Sums of each manifold defect per method (``meshcheck.topology_violations``)."""
    head = "method | meshes not manifold | " + " | ".join(d.replace("_", " ") for d in DEFECTS)
    lines = [f"| {head} |", "|" + "---|" * (head.count("|") + 1)]
    for method in methods:
        mine = [r for r in rows if r["method"] == method]
        if mine:
            bad = [r["name"] for r in mine if not int(r["manifold"])]
            sums = [str(sum(int(r[d]) for r in mine)) for d in DEFECTS]
            lines.append(f"| {LABELS[method]} | {len(bad)}/{len(mine)}"
                         f"{' (' + ', '.join(bad) + ')' if bad else ''} | " + " | ".join(sums)
                         + " |")
    return "\n".join(lines)


def per_mesh_table(rows, methods) -> str:
    head = "mesh | kind | " + " | ".join(LABELS[m] for m in methods)
    lines = [f"| {head} |", "|" + "---|" * (head.count("|") + 1)]
    for name in dict.fromkeys(r["name"] for r in rows):
        cells = []
        for method in methods:
            hit = [r for r in rows if r["name"] == name and r["method"] == method]
            if not hit:
                cells.append("–")
                continue
            r = hit[0]
            ef1 = "–" if math.isnan(float(r["ef1"])) else f"{float(r['ef1']):.2f}"
            flag = "" if int(r["manifold"]) else " ✗"
            cells.append(f"{float(r['cd']) * 1e5:.2f} / {ef1}{flag}")
        lines.append(f"| {name} | {hit[0]['kind']} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def timing_table(rows, methods) -> str:
    resolutions = sorted({int(r["res"]) for r in rows})
    head = "mesh | method | " + " | ".join(f"{r}³ s (triangles)" for r in resolutions)
    lines = [f"| {head} |", "|" + "---|" * (head.count("|") + 1)]
    for name in dict.fromkeys(r["name"] for r in rows):
        for method in methods:
            cells = []
            for res in resolutions:
                hit = [r for r in rows if r["name"] == name and r["method"] == method
                       and int(r["res"]) == res]
                cells.append(f"{float(hit[-1]['min_s']):.2f} ({int(hit[-1]['faces']):,})"
                             if hit else "–")
            if any(c != "–" for c in cells):
                lines.append(f"| {name} | {LABELS[method]} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _fmt(value: float, digits: int) -> str:
    return "–" if math.isnan(value) else f"{value:.{digits}f}"


def _nanmean(values) -> float:
    values = np.asarray(values, dtype=np.float64)
    values = values[np.isfinite(values)]
    return float(values.mean()) if len(values) else math.nan


def read_rows(path: Path) -> list[dict]:
    if not path.exists():
        return []
    with open(path, newline="") as handle:
        return list(csv.DictReader(handle))


def append_row(path: Path, row: dict) -> None:
    """Append one row; the header is the union of the columns seen so far (rewritten if new)."""
    rows = read_rows(path) + [row]
    columns = list(dict.fromkeys(k for r in rows for k in r))
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=columns, restval="")
        writer.writeheader()
        writer.writerows(rows)


def parse_args(argv):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("command", choices=("measure", "timing", "meshes", "render", "tables"))
    parser.add_argument("--res", type=int, nargs="+", default=[64])
    parser.add_argument("--methods", nargs="+", default=list(METHODS), choices=METHODS)
    parser.add_argument("--kinds", default="cad,organic",
                        help="MANIFEST.csv kinds for measure (e.g. cad,organic,print (Thingi10K))")
    parser.add_argument("--meshes", default=f"fandisk,{BEVELLED_CUBE}",
                        help="comma-separated mesh names for timing/meshes/render")
    parser.add_argument("--bevelled-cube", action="store_true",
                        help="measure: add the bevelled cube to the dev meshes")
    parser.add_argument("--limit", type=int, help="measure: only the first N meshes")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--threads", type=int, default=2, help="torch CPU threads (AGNDC)")
    parser.add_argument("--out", type=Path, default=OUT)
    parser.add_argument("--images", type=Path, default=ROOT / "docs" / "images")
    parser.add_argument("--dpi", type=int, default=100)
    parser.add_argument("--elev", type=float, default=25.0)
    parser.add_argument("--azim", type=float, default=-60.0)
    parser.add_argument("--zoom", type=float, default=1.0, help="render: magnify the centre")
    parser.add_argument("--tag", default="", help="render: suffix of the PNG name")
    return parser.parse_args(argv)


def main(argv=None) -> int:
    args = parse_args(sys.argv[1:] if argv is None else argv)
    args.out.mkdir(parents=True, exist_ok=True)
    args.images.mkdir(parents=True, exist_ok=True)
    {"measure": cmd_measure, "timing": cmd_timing, "meshes": cmd_meshes, "render": cmd_render,
     "tables": cmd_tables}[args.command](args)
    return 0


if __name__ == "__main__":
    status = main()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(status)  # bpy 4.5 can hang at interpreter exit (docs/blender.md)
