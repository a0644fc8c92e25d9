"""Low poly (``agndc_core/decimate.py``) against Blender's Decimate modifier and Voxel Remesh
with adaptivity, at the same face counts.

    .venv-bpy/bin/python research/compare_low_poly.py measure --res 64 [--meshes a,b]
    .venv/bin/python research/compare_low_poly.py render --mesh fandisk --res 64   # matplotlib
    .venv/bin/python research/compare_low_poly.py tables --res 64                  # markdown

Per CAD dev mesh (``../shared/data/dev/MANIFEST.csv``, kind ``cad``), voxelised at ``--res``:

* ``agndc``: ``remesh_mesh(method="agndc")``, F faces;
* ``agndc_lp25`` / ``agndc_lp10``: the same mesh decimated to 25 % / 10 % of F
  (``decimate(target_faces=...)``, with the pipeline's one-voxel tolerance limit);
* ``agndc_err25``: the same mesh decimated with a 0.25-voxel error bound;
* ``blender_dec25`` / ``blender_dec10``: Blender's Decimate modifier (Collapse, triangulated)
  on the AGNDC mesh, ratio 25 % / 10 %;
* ``voxel`` and ``voxel_ad25`` / ``voxel_ad10``: Blender's Remesh modifier in Voxel mode at
  the same voxel size (compare_voxel_remesh.py's convention), adaptivity 0, then the
  adaptivity bisected (8 steps) so that its triangle count is closest to 25 % / 10 % of F.

Every output is scored against the source with ``agndc_core.metrics.evaluate`` (CD, F1, NC, ECD,
EF1, 100k samples) and checked with ``meshcheck.topology_violations``. Rows go to
``--out/rows_<res>.csv``; ``--save`` meshes (npz) feed ``render``.
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
sys.path.insert(0, str(ROOT / "research"))  # compare_voxel_remesh beside it

OUT = ROOT / "out" / "low_poly"
SHARES = (25, 10)
METHODS = ("agndc", "agndc_err25", *(f"agndc_lp{s}" for s in SHARES),
           *(f"blender_dec{s}" for s in SHARES), "voxel", *(f"voxel_ad{s}" for s in SHARES))
LABELS = {"agndc": "AGNDC", "agndc_err25": "AGNDC + low poly 0.25 voxel",
          **{f"agndc_lp{s}": f"AGNDC + low poly {s} %" for s in SHARES},
          **{f"blender_dec{s}": f"AGNDC + Blender Decimate {s} %" for s in SHARES},
          "voxel": "Blender Voxel Remesh",
          **{f"voxel_ad{s}": f"Blender Voxel Remesh, adaptivity ≈ {s} %" for s in SHARES}}
METRICS = ("cd", "f1", "nc", "ecd", "ef1")
ADAPTIVITY_STEPS = 8


def blender_decimate(obj, ratio: float):
    """Blender's Decimate modifier (Collapse, ratio, triangulated): (vertices, faces)."""
    from compare_voxel_remesh import evaluated_triangles

    modifier = obj.modifiers.new("decimate", "DECIMATE")
    modifier.decimate_type, modifier.ratio, modifier.use_collapse_triangulate = \
        "COLLAPSE", ratio, True
    try:
        return evaluated_triangles(obj)
    finally:
        obj.modifiers.remove(modifier)


def voxel_remesh(obj, h: float, adaptivity: float):
    """Blender's Remesh modifier, Voxel mode (triangulated): (vertices, faces)."""
    from compare_voxel_remesh import evaluated_triangles

    modifier = obj.modifiers.new("remesh", "REMESH")
    modifier.mode, modifier.voxel_size, modifier.adaptivity = "VOXEL", h, adaptivity
    try:
        return evaluated_triangles(obj)
    finally:
        obj.modifiers.remove(modifier)


def voxel_for_faces(obj, h: float, target: int):
    """The adaptivity (bisected in [0, 1]) whose Voxel Remesh triangle count is closest to
    ``target``: (vertices, faces, adaptivity)."""
    lo, hi, best = 0.0, 1.0, None
    for _ in range(ADAPTIVITY_STEPS):
        mid = (lo + hi) / 2
        v, f = voxel_remesh(obj, h, mid)
        if best is None or abs(len(f) - target) < abs(len(best[1]) - target):
            best = (v, f, mid)
        lo, hi = (mid, hi) if len(f) > target else (lo, mid)
    return best


def run_mesh(name, vertices, faces, resolution, save: Path | None) -> list[dict]:
    """Every method's row for one mesh."""
    from compare_voxel_remesh import _bpy, mesh_object, voxel_size

    from agndc_core.decimate import decimate
    from agndc_core.pipeline import TARGET_TOLERANCE, remesh_mesh

    bpy = _bpy()  # a temporary Blender user folder unless one is set
    bpy.ops.wm.read_homefile(use_empty=True)
    start = time.perf_counter()
    result = remesh_mesh(vertices, faces, resolution=resolution, method="agndc")
    outputs = {"agndc": (result.vertices, result.faces, time.perf_counter() - start)}
    full = len(result.faces)
    # decimation in the grid's voxel units, as remesh(decimate_error=, target_faces=) does
    voxel = float(result.grid.voxel_size.max())
    start = time.perf_counter()
    v, f = decimate(result.vertices, result.faces, max_error=0.25 * voxel)
    outputs["agndc_err25"] = (v, f, time.perf_counter() - start)
    agndc_obj = mesh_object(result.vertices, result.faces, "agndc")
    source_obj = mesh_object(vertices, faces, "source")
    h = voxel_size(vertices, resolution)
    outputs["voxel"] = (*voxel_remesh(source_obj, h, 0.0), 0.0)
    for share in SHARES:
        target = full * share // 100
        start = time.perf_counter()
        v, f = decimate(result.vertices, result.faces, target_faces=target,
                        max_tolerance=TARGET_TOLERANCE * voxel)
        outputs[f"agndc_lp{share}"] = (v, f, time.perf_counter() - start)
        start = time.perf_counter()
        v, f = blender_decimate(agndc_obj, share / 100)
        outputs[f"blender_dec{share}"] = (v, f, time.perf_counter() - start)
        v, f, adaptivity = voxel_for_faces(source_obj, h, target)
        outputs[f"voxel_ad{share}"] = (v, f, adaptivity)
    rows = []
    for method, (v, f, extra) in outputs.items():
        rows.append({"mesh": name, "method": method, "faces": len(f), "share": len(f) / full,
                     "extra": round(float(extra), 3), **score(v, f, vertices, faces)})
        if save is not None:
            save.mkdir(parents=True, exist_ok=True)
            np.savez_compressed(save / f"{name}_{method}.npz", vertices=v, faces=f)
    if save is not None:
        np.savez_compressed(save / f"{name}_source.npz", vertices=vertices, faces=faces)
    return rows


def score(v, f, vertices, faces) -> dict:
    from agndc_core.meshcheck import topology_violations
    from agndc_core.metrics import evaluate

    metrics = evaluate(v, f, vertices, faces)
    defects = topology_violations(v, f)
    closed = all(n == 0 for k, n in defects.items() if k != "unused_vertices")
    return {**{k: metrics[k] for k in METRICS}, "closed_manifold": int(closed)}


def cmd_measure(args) -> None:
    import compare_voxel_remesh

    from agndc_core.gridio import load_mesh

    compare_voxel_remesh.DATA = args.data
    meshes = compare_voxel_remesh.dev_meshes(["cad"])
    if args.meshes:
        meshes = [m for m in meshes if m[0] in args.meshes.split(",")]
    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / f"rows_{args.res}.csv"
    rows = []
    for name, _, mesh_path in meshes:
        vertices, faces = load_mesh(mesh_path)
        save = args.out / f"meshes_{args.res}" if name in args.save.split(",") else None
        rows += run_mesh(name, vertices, faces, args.res, save)
        with open(path, "w", newline="") as handle:  # after every mesh: a partial run counts
            writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
            writer.writeheader()
            writer.writerows(rows)
        print(f"{name}: " + ", ".join(f"{r['method']} {r['faces']}" for r in rows
                                      if r["mesh"] == name), flush=True)
    print(f"written: {path}")


def cmd_tables(args) -> None:
    with open(args.out / f"rows_{args.res}.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    print(f"| method ({len({r['mesh'] for r in rows})} CAD meshes, {args.res}³) | faces "
          "(share of AGNDC) | CD×10⁵ ↓ | F1 ↑ | NC ↑ | ECD×10² ↓ | EF1 ↑ | closed 2-manifold |")
    print("|---|---|---|---|---|---|---|---|")
    for method in METHODS:
        chosen = [r for r in rows if r["method"] == method]
        if not chosen:
            continue

        def mean(key, chosen=chosen):
            return float(np.nanmean([float(r[key]) for r in chosen]))

        print(f"| {LABELS[method]} | {mean('faces'):,.0f} ({mean('share'):.1%}) | "
              f"{mean('cd') * 1e5:.2f} | {mean('f1'):.3f} | {mean('nc'):.3f} | "
              f"{mean('ecd') * 1e2:.3f} | {mean('ef1'):.3f} | "
              f"{sum(int(r['closed_manifold']) for r in chosen)}/{len(chosen)} |")


def cmd_render(args) -> None:
    """Undecimated AGNDC, low poly at 10 %, Blender Decimate at the same ratio (wireframe)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from compare_voxel_remesh import _quantize, draw_mesh

    folder = args.out / f"meshes_{args.res}"
    columns = ["agndc", "agndc_lp10", "blender_dec10"]
    meshes = {c: np.load(folder / f"{args.mesh}_{c}.npz") for c in ["source", *columns]}
    reference = meshes["source"]["vertices"]
    fig = plt.figure(figsize=(4.0 * len(columns), 3.3), dpi=args.dpi)
    for index, column in enumerate(columns):
        ax = fig.add_subplot(1, len(columns), index + 1, projection="3d")
        v, f = meshes[column]["vertices"], meshes[column]["faces"]
        draw_mesh(ax, v, f, reference, elev=args.elev, azim=args.azim, zoom=args.zoom)
        ax.set_title(f"{LABELS[column]}\n{len(f):,} triangles", fontsize=10, y=0.95)
    fig.subplots_adjust(left=0, right=1, bottom=0, top=0.95, wspace=0)
    png = args.images / f"low_poly_{args.mesh}_{args.res}.png"
    fig.savefig(png)
    plt.close(fig)
    _quantize(png)
    print(f"{png}  {png.stat().st_size / 1e3:.0f} KB")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(required=True)
    p = sub.add_parser("measure")
    p.add_argument("--res", type=int, default=64)
    p.add_argument("--meshes", default="", help="comma list of CAD mesh stems (default: all)")
    p.add_argument("--save", default="fandisk", help="comma list of meshes to save for render")
    p.add_argument("--data", type=Path, default=ROOT.parent / "shared" / "data" / "dev",
                   help="the dev meshes' folder (with MANIFEST.csv)")
    p.set_defaults(func=cmd_measure)
    p = sub.add_parser("tables")
    p.add_argument("--res", type=int, default=64)
    p.set_defaults(func=cmd_tables)
    p = sub.add_parser("render")
    p.add_argument("--res", type=int, default=64)
    p.add_argument("--mesh", default="fandisk")
    p.add_argument("--images", type=Path, default=ROOT / "docs" / "images")
    p.add_argument("--dpi", type=int, default=80)
    p.add_argument("--elev", type=float, default=25)
    p.add_argument("--azim", type=float, default=-60)
    p.add_argument("--zoom", type=float, default=1.0)
    p.set_defaults(func=cmd_render)
    for p in sub.choices.values():
        p.add_argument("--out", type=Path, default=OUT)
    args = parser.parse_args()
    args.func(args)


if __name__ == "__main__":
    main()
