"""Batch remeshing inside Blender, through the same code path as the "Remesh with AGNDC" operator.

    blender -b --factory-startup --python-exit-code 1 -P scripts/agndc_batch.py -- \
        --input IN --output OUT [--res 64] [--method agndc|undc|mc] [--compare-mc] [--threads N]
    python scripts/agndc_batch.py -- --input IN --output OUT ...      # with the bpy module

IN is a mesh file (.obj .ply .stl .off .glb .gltf), a grid file (.npy .npz .binvox .vox .nii
.nii.gz) or a folder of them. OUT is a folder (created) that receives ``<stem>_AGNDC.<ext>``
(and ``<stem>_MC.<ext>`` with --compare-mc) plus ``agndc_batch.csv`` (one row per output with
faces and times, one row per failed input with its error). With a single input file, OUT may
also be a mesh file name. Meshes are written in the input's own coordinates (grids: world units).
The exit status is 1 when any input failed (every other input is still processed), 2 for bad
arguments.

The add-on code is taken from, in order: an enabled AGNDC add-on, an installed AGNDC extension
(enabled for this run), or the ``agndc_blender`` folder of the checkout this script lives in.

Shared with ``agndc batch`` (``agndc_core.batch``): finding the inputs in a folder, the CSV
table (written row by row and flushed, so a crash keeps the rows of the inputs already done)
and the output writing (``gridio.save_mesh``: a temporary name renamed into place, never a
partial file). The remeshing itself goes through the add-on's ``remesh_object``/``import_grid``
(Blender objects), so its results are what the operator gives; for many files on many cores or
a cluster, use ``agndc batch`` outside Blender.
"""

import argparse
import importlib
import os
import sys
import time
import traceback
from pathlib import Path

import bpy

EXTENSION_ID = "agndc_remesher"
CSV_NAME = "agndc_batch.csv"
CSV_FIELDS = ("input", "output", "method", "status", "faces", "vertices", "seconds",
              "remesh_seconds", "cd", "error")


def parse_args(argv):
    argv = argv[argv.index("--") + 1:] if "--" in argv else []
    parser = argparse.ArgumentParser(prog="agndc_batch.py", description=__doc__.split("\n\n")[0])
    parser.add_argument("--input", required=True, type=Path, help="mesh/grid file or folder")
    parser.add_argument("--output", required=True, type=Path, help="output folder (or file)")
    parser.add_argument("--res", type=int, default=64, help="voxels along the longest side of "
                        "each mesh (8-256; grids keep their own resolution)")
    parser.add_argument("--method", default="agndc", choices=("agndc", "undc", "mc"))
    parser.add_argument("--compare-mc", action="store_true",
                        help="also write the marching-cubes mesh of the same grid")
    parser.add_argument("--no-normal-filter", action="store_true",
                        help="AGNDC/UNDC: keep the mesh as contoured (by default it is denoised, "
                        "creases kept: agndc_core/normalfilter.py)")
    low_poly = parser.add_mutually_exclusive_group()
    low_poly.add_argument("--decimate-error", type=float, metavar="VOXELS",
                          help="Low Poly: decimate, the surface moved by at most VOXELS voxels")
    low_poly.add_argument("--target-faces", type=int, metavar="N",
                          help="Low Poly: decimate to at most N faces")
    parser.add_argument("--threads", type=int, default=0, help="CPU threads (0 = automatic)")
    parser.add_argument("--format", default=".obj", help="output mesh extension (default .obj)")
    parser.add_argument("--checkpoint", help="custom weights (.safetensors)")
    parser.add_argument("--no-distance", action="store_true",
                        help="skip the Chamfer distance of each result to its source mesh")
    parser.add_argument("--per-label", action="store_true",
                        help="label maps (.nii .nii.gz .npy .npz): one output per label, named "
                        "<input>_label-<value> (docs/labelmaps.md)")
    parser.add_argument("--labels", default="",
                        help="with --per-label: only these labels, e.g. 1,3,7")
    return parser.parse_args(argv)


def find_addon():
    """The add-on package: enabled, else installed (and enabled now), else this checkout's."""
    import addon_utils

    for name in bpy.context.preferences.addons.keys():
        if name.rsplit(".", 1)[-1] in (EXTENSION_ID, "agndc_blender"):
            return importlib.import_module(name)
    for repo in bpy.context.preferences.extensions.repos:
        if repo.enabled and (Path(repo.directory) / EXTENSION_ID).is_dir():
            name = f"bl_ext.{repo.module}.{EXTENSION_ID}"
            if addon_utils.enable(name, default_set=False) is not None:
                return importlib.import_module(name)
    checkout = Path(__file__).resolve().parents[1]
    if (checkout / "agndc_blender" / "__init__.py").is_file():
        sys.path.insert(0, str(checkout))  # a script, not the add-on: allowed to do this
        return importlib.import_module("agndc_blender")
    raise SystemExit("AGNDC add-on not found: install the extension zip, or run this script "
                     "from a checkout of the repository")


def list_inputs(path: Path, batch) -> list[Path]:
    """The mesh and grid files of a folder (not its subfolders), or the one file given."""
    return batch.find_files(path, recursive=False) if path.is_dir() else [path]


def output_path(args, source: Path, stem: str, method: str, single: bool, suffixes,
                several: bool = False) -> Path:
    """Where one result is written; ``several``: the input gave several results of a method
    (the labels of a label map, the models of a .vox), named by their own ``stem`` even when
    ``--output`` names a file."""
    if single and args.output.suffix and not args.output.is_dir():
        first = args.output
        if several:
            first = first.with_name(f"{stem}{first.suffix}")
        return first if method == args.method else first.with_name(
            f"{first.stem}_{suffixes[method]}{first.suffix}")
    return args.output / f"{stem}_{suffixes[method]}{args.format}"


def process(path: Path, args, addon, settings, single: bool) -> list[dict]:
    """Remesh one input through ``remesh_object``/``import_grid``; rows for the CSV."""
    remesh, core, mesh_io = addon.remesh, addon.core, addon.mesh_io
    start = time.perf_counter()
    if core.gridio.is_grid_path(path):
        # one job per label of a label map (--per-label), else one for the file
        jobs = remesh.grid_jobs([path], settings)
        remesh.compute_jobs(jobs, settings)
        reports = remesh.apply_jobs(jobs, settings)
    else:
        vertices, faces = core.gridio.load_mesh(path)
        name = path.name.rsplit(".", 1)[0]
        obj = bpy.data.objects.new(name, mesh_io.new_mesh(name, vertices, faces))
        bpy.context.scene.collection.objects.link(obj)
        try:
            reports = [remesh.remesh_object(obj, settings)]
        finally:
            _remove(obj)
    if len(reports) == 1 and reports[0].error is not None:
        raise core.errors.AGNDCError(reports[0].error)
    rows = []
    for report in reports:
        if report.error is not None:  # one label of several failed: the others still count
            rows.append(dict(input=str(path), output=report.source, status="failed",
                             error=report.error))
            continue
        for item in report.made:
            vertices, faces = mesh_io.mesh_arrays(item.object.data)
            out = output_path(args, path, report.source, item.method, single, remesh.SUFFIXES,
                              several=len(reports) > 1)
            out.parent.mkdir(parents=True, exist_ok=True)
            core.gridio.save_mesh(vertices, faces, out)
            rows.append(dict(input=str(path), output=str(out), method=item.method, status="ok",
                             faces=len(faces), vertices=len(vertices),
                             seconds=f"{time.perf_counter() - start:.3f}",
                             remesh_seconds=f"{item.seconds:.3f}",
                             cd="" if item.cd is None else f"{item.cd:.6g}", error=""))
            _remove(item.object)
    return rows


def _remove(obj) -> None:
    mesh = obj.data
    bpy.data.objects.remove(obj)
    if mesh is not None and mesh.users == 0:
        bpy.data.meshes.remove(mesh)


def main(argv) -> int:
    try:
        args = parse_args(argv)
    except SystemExit as exc:
        return 2 if exc.code else 0
    addon = find_addon()
    remesh = importlib.import_module(f"{addon.__name__}.remesh")
    core = importlib.import_module(f"{addon.__name__}._core")
    mesh_io = importlib.import_module(f"{addon.__name__}.mesh_io")
    batch = importlib.import_module(f"{core.core.__name__}.batch")  # agndc_core.batch
    addon = argparse.Namespace(remesh=remesh, core=core, mesh_io=mesh_io)
    settings = remesh.Settings(resolution=args.res, method=args.method, threads=args.threads,
                               compare_mc=args.compare_mc, checkpoint=args.checkpoint,
                               distance=not args.no_distance,
                               normal_filter=not args.no_normal_filter,
                               decimate_error=args.decimate_error,
                               target_faces=args.target_faces,
                               per_label=args.per_label, labels=args.labels)
    if not args.input.exists():
        print(f"agndc_batch: error: {args.input}: no such file or folder", file=sys.stderr)
        return 2
    inputs = list_inputs(args.input, batch)
    if not inputs:
        print(f"agndc_batch: error: no mesh or grid files in {args.input}", file=sys.stderr)
        return 2
    single = args.input.is_file()
    if not (single and args.output.suffix):
        args.output.mkdir(parents=True, exist_ok=True)
    csv_dir = args.output.parent if single and args.output.suffix else args.output
    csv_dir.mkdir(parents=True, exist_ok=True)
    table = batch.CsvLog(csv_dir / CSV_NAME, CSV_FIELDS)
    failures = 0
    try:
        for path in inputs:
            try:
                new_rows = process(path, args, addon, settings, single)
            except core.errors.AGNDCError as exc:
                failures += 1
                print(f"FAILED {path}: {exc}", file=sys.stderr)
                table.write(dict(input=str(path), status="failed", error=str(exc)))
                continue
            except Exception as exc:  # a bug: keep going, but show the traceback and fail
                failures += 1
                traceback.print_exc()
                table.write(dict(input=str(path), status="failed", error=repr(exc)))
                continue
            failures += any(row["status"] == "failed" for row in new_rows)
            for row in new_rows:
                table.write(row)
                if row["status"] == "failed":
                    print(f"FAILED {row['output']}: {row['error']}", file=sys.stderr)
                    continue
                print(f"{row['output']}: {row['faces']} faces, {row['remesh_seconds']} s"
                      + (f", CD {float(row['cd']) * 1e5:.2f}e-5" if row["cd"] else ""))
    finally:
        table.close()
    # an input with a failed label counts as failed (its other labels are still written)
    print(f"{len(inputs) - failures}/{len(inputs)} inputs done, {failures} failed; "
          f"table: {csv_dir / CSV_NAME}")
    return 1 if failures else 0


def run(argv) -> int:
    """main() with every way out turned into an exit status (never an interpreter exit)."""
    try:
        return main(argv)
    except SystemExit as exc:  # e.g. find_addon's message
        if isinstance(exc.code, int):
            return exc.code
        print(f"agndc_batch: error: {exc.code}", file=sys.stderr)
        return 2
    except BaseException:
        traceback.print_exc()
        return 1


if __name__ == "__main__":
    status = run(sys.argv)
    sys.stdout.flush()
    sys.stderr.flush()
    # os._exit: Blender 3.4 with torch segfaults and bpy 4.5 can hang in normal interpreter exit
    os._exit(status)
