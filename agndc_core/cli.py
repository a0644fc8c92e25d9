"""``agndc`` command line: remesh, batch, eval, demo, train.

Every user-facing failure is an ``AGNDCError``; the CLI prints its message and exits with 2.
"""

from __future__ import annotations

import argparse
import logging
import sys
import warnings
from contextlib import contextmanager
from pathlib import Path

from .errors import AGNDCError
from .methods import METHODS, REGISTRY
from .options import RemeshOptions


def main(argv=None) -> int:
    # the library reports through ``logging`` (e.g. a resumed training run); the CLI shows it
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    parser = _parser()
    args = parser.parse_args(argv)
    if not hasattr(args, "func"):
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except AGNDCError as exc:
        print(f"agndc: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("agndc: cancelled", file=sys.stderr)
        return 130


def _parser() -> argparse.ArgumentParser:
    from . import __version__

    parser = argparse.ArgumentParser(prog="agndc", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers()

    p = sub.add_parser("remesh", help="reconstruct a mesh from a grid file or a mesh")
    p.add_argument("input", type=Path, help="mesh (.obj .ply .stl .glb .off) or grid "
                   "(.npy .npz .binvox .vox .nii .nii.gz)")
    p.add_argument("-o", "--output", type=Path, required=True, help="output .obj/.ply/.stl/.glb")
    p.add_argument("--method", choices=METHODS, default="agndc",
                   help="; ".join(f"{m.name}: {m.description}" for m in REGISTRY))
    _add_remesh_options(p)
    p.add_argument("--threads", type=int, help="CPU threads for the network")
    p.add_argument("--no-colors", dest="colors", action="store_false",
                   help="coloured grids (.vox): write plain geometry (by default each face "
                   "takes the colour of the nearest voxel: .glb one material per colour, .ply "
                   "face colours; .obj and .stl are always plain)")
    p.add_argument("--quads", action="store_true",
                   help=".obj/.ply output of a dual method: join each planar, convex pair of "
                   "triangles of one dual-contouring quad into a quad, the rest stays "
                   "triangles (docs/quads.md); .stl/.glb and a coloured .ply hold triangles "
                   "only, and marching cubes and low poly make no quads")
    _add_label_options(p, "beside OUTPUT as <name>_label-<value>.<ext>")
    p.set_defaults(func=_cmd_remesh)

    p = sub.add_parser("batch", help="remesh many files (files, folders, manifests) into a "
                       "folder, resumable, on local processes or a Dask cluster",
                       description="Each input becomes OUTDIR/<name>.<format> and a row of "
                       "OUTDIR/batch.csv. Exit status: 0 all done, 1 some input failed, "
                       "2 usage error. See docs/batch.md.")
    p.add_argument("inputs", nargs="+", type=Path, metavar="INPUT",
                   help="mesh or grid file, folder (searched recursively) or manifest "
                   "(.txt: a path a line; .csv: an input column, optional output column)")
    p.add_argument("-o", "--output", type=Path, required=True, metavar="OUTDIR")
    p.add_argument("--format", default="ply", choices=("ply", "obj", "stl", "glb"))
    p.add_argument("--method", choices=METHODS, default="agndc")
    _add_remesh_options(p)
    p.add_argument("--workers", type=int, help="worker processes (default: the CPU cores)")
    p.add_argument("--engine", choices=("local", "dask"),
                   help="local (a process pool; default) or dask (a Dask distributed "
                   "cluster: --scheduler, else a LocalCluster of --workers processes)")
    p.add_argument("--scheduler", metavar="ADDRESS", help="Dask scheduler, e.g. tcp://host:8786")
    p.add_argument("--threads", type=int,
                   help="torch threads per job (default: the cores divided by the workers)")
    p.add_argument("--overwrite", action="store_true",
                   help="redo outputs that already exist and are newer than their input")
    _add_label_options(p, "as OUTDIR/<name>_label-<value>.<format>, one batch.csv row each; "
                       "a label missing from a file is that label's failed row")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_batch)

    p = sub.add_parser("eval", help="evaluate methods on a folder of meshes (CSV + markdown)")
    p.add_argument("folder", type=Path)
    p.add_argument("-o", "--out", type=Path, default=Path("out/eval"))
    p.add_argument("--methods", default="mc,oracle",
                   help=f"comma list of {','.join(METHODS)}; surfacenets, undc or agndc with "
                        "'+bounds' also get the mesh's bounding box "
                        "(agndc_core/study/evaluate.py); "
                        "LABEL=METHOD scores a method under a label of its own, e.g. "
                        "cpu3=agndc with --checkpoint cpu3=PATH beside the shipped agndc")
    p.add_argument("--res", type=int, default=64)
    p.add_argument("--samples", type=int, default=100_000)
    p.add_argument("--limit", type=int, help="only the first N meshes")
    _add_normal_filter_option(p)
    p.add_argument("--checkpoint", action="append", default=[], metavar="METHOD=PATH",
                   help="weights for a learned method (or a LABEL=METHOD label) instead of "
                   "the shipped ones, e.g. agndc=runs/x/final.safetensors (repeatable)")
    p.add_argument("--shifts", type=int, default=0, metavar="K",
                   help="score every mesh on K grids moved by seeded random sub-voxel shifts "
                   "instead of the centred grid; means are over meshes and shifts, and the "
                   "means of each shift are printed too (default 0: the centred grid)")
    p.set_defaults(func=_cmd_eval)

    p = sub.add_parser("demo", help="generate a CAD part, voxelise, reconstruct, compare")
    p.add_argument("-o", "--out", type=Path, default=Path("out/demo"))
    p.add_argument("--seed", type=int, default=7)
    p.add_argument("--res", type=int, default=64)
    p.add_argument("--no-source-bounds", dest="source_bounds", action="store_false",
                   help="surface nets, UNDC and AGNDC from the grid alone (by default they also "
                        "get the part's bounding box, as `agndc remesh` does for a mesh)")
    p.set_defaults(func=_cmd_demo)

    from .study.report import add_parser as add_report_parser

    add_report_parser(sub)
    try:
        from .training.cli import add_train_parser
    except ImportError:  # training code is not shipped inside the Blender extension
        add_train_parser = None
    if add_train_parser is not None:
        add_train_parser(sub)
    return parser


def _add_remesh_options(p) -> None:
    """What ``agndc remesh`` and ``agndc batch`` share (``pipeline.remesh_file``'s options)."""
    size = p.add_mutually_exclusive_group()
    size.add_argument("--res", type=int, default=64,
                      help="voxels on the longest side (mesh input; grids are used as they are)")
    size.add_argument("--voxel-size", type=float, metavar="S",
                      help="instead of --res: voxels of at most S world units (mesh input)")
    p.add_argument("--checkpoint", type=Path, help="weights (.safetensors); default: shipped")
    p.add_argument("--model-index", type=int, default=0, help=".vox files: which model")
    p.add_argument("--device", default="cpu", help="torch device, e.g. cuda")
    p.add_argument("--min-component-faces", type=int, default=0)
    p.add_argument("--no-flat-patches", dest="flat_patches", action="store_false",
                   help="learned methods: keep the network's raw vertices on flat voxel faces "
                        "(by default each flat patch that is not a terrace of a slanted or "
                        "curved surface is given one depth, the terraces of a slightly "
                        "tilted plane one plane, and a recessed floor or plateau the network "
                        "sees flat the middle of its layer, so flat faces come out flat)")
    _add_normal_filter_option(p)
    p.add_argument("--no-source-bounds", dest="source_bounds", action="store_false",
                   help="mesh input, dual methods: use the voxel grid alone (by default the "
                        "faces that bound the mesh are put on its bounding box, which the grid "
                        "cannot place within a voxel, and no vertex lies beyond it)")
    p.add_argument("--decimate-error", type=float, metavar="VOXELS",
                   help="low poly: merge flat regions into large triangles, keeping creases and "
                        "a closed mesh, with the surface moved by at most VOXELS voxels (e.g. "
                        "0.25; docs/experiments/low-poly.md)")
    p.add_argument("--target-faces", type=int, metavar="N",
                   help="low poly: decimate to about N faces (at most N; with --decimate-error "
                        "the bound stops it first)")


def _add_label_options(p, written: str) -> None:
    """--per-label and --labels, which ``agndc remesh`` and ``agndc batch`` share; ``written``
    says where the label meshes go."""
    p.add_argument("--per-label", action="store_true",
                   help="label maps (.nii .nii.gz .npy .npz): one mesh per label (each "
                   f"positive value), written {written} (docs/labelmaps.md)")
    p.add_argument("--labels", metavar="LIST",
                   help="only these labels, e.g. 1,3,7 (implies --per-label)")


def _add_normal_filter_option(p) -> None:
    p.add_argument("--no-normal-filter", dest="normal_filter", action="store_false",
                   help="learned methods: keep the contoured mesh as it is (by default it is "
                        "denoised by bilateral normal filtering, which keeps its creases: "
                        "agndc_core/normalfilter.py)")


def _progress_bar(desc: str):
    """A tqdm bar driven by remesh's progress(fraction, message) callback."""
    from tqdm import tqdm

    bar = tqdm(total=100, desc=desc, unit="%", bar_format="{l_bar}{bar}| {postfix}")

    def update(fraction: float, message: str) -> None:
        bar.n = int(round(100 * fraction))
        bar.set_postfix_str(message)
        bar.refresh()

    return bar, update


def _cmd_remesh(args) -> int:
    from .colors import result_colors
    from .gridio import save_mesh
    from .pipeline import remesh_file

    if args.per_label or args.labels:
        return _remesh_labels(args)
    bar, update = _progress_bar(args.input.name)
    try:
        with _merged_labels_hint():
            result = remesh_file(args.input, options_from_args(args), progress=update)
    finally:
        bar.close()
    colors = result_colors(result) if args.colors else {}
    polygons = result.polygons() if args.quads else None
    save_mesh(result.vertices, result.faces, args.output, polygons=polygons, **colors)
    used = f" ({len(set(colors['face_colors'].tolist()))} colours)" if colors else ""
    print(f"{args.output}: {_result_line(result)}{used}")
    if polygons is not None:
        print(_quads_line(polygons, args.output, result.face_quads is None, bool(colors)))
    return 0


def _quads_line(polygons, output: Path, no_quads: bool, colored: bool) -> str:
    """What ``--quads`` wrote, or why it wrote triangles."""
    from .gridio import polygon_extensions

    if no_quads:
        return "--quads: marching cubes and low poly make triangles only; triangles written"
    if output.suffix.lower() not in polygon_extensions(colored):
        kind = "a coloured " if colored and output.suffix.lower() == ".ply" else ""
        return f"--quads: {kind}{output.suffix} holds triangles only; triangles written"
    return (f"--quads: {len(polygons.quads)} quads and {len(polygons.triangles)} triangles "
            f"({100 * polygons.quad_fraction:.1f} % quads)")


def options_from_args(args) -> RemeshOptions:
    """The ``RemeshOptions`` of ``agndc remesh`` / ``agndc batch``'s flags (``_add_remesh_options``
    names each flag after its field)."""
    checkpoint = str(args.checkpoint) if args.checkpoint else None
    return RemeshOptions(method=args.method, resolution=args.res, voxel_size=args.voxel_size,
                         model_index=args.model_index, checkpoint=checkpoint,
                         device=args.device, threads=args.threads,
                         min_component_faces=args.min_component_faces,
                         flat_patches=args.flat_patches, normal_filter=args.normal_filter,
                         source_bounds=args.source_bounds, decimate_error=args.decimate_error,
                         target_faces=args.target_faces)


def _result_line(result) -> str:
    stages = ", ".join(f"{k} {v:.2f}s" for k, v in result.timings.items())
    return (f"{len(result.vertices)} vertices, {len(result.faces)} faces, {result.method}, "
            f"{result.seconds:.2f} s ({stages})")


def _remesh_labels(args) -> int:
    """``agndc remesh --per-label``: each label's mesh written as soon as it is made."""
    from .gridio import save_mesh
    from .labelmaps import iter_remesh_labels, label_output_path, load_label_map

    volume = load_label_map(args.input)  # a mesh or a one-solid grid file: an error naming it
    counts = volume.labels()
    chosen = volume.select(args.labels)  # unknown labels fail before any work
    print(f"{args.input.name}: {len(counts)} labels, meshing {len(chosen)}")
    bar, update = _progress_bar(args.input.name)
    try:
        for label, result in iter_remesh_labels(volume, options_from_args(args), labels=chosen,
                                                progress=update):
            path = label_output_path(args.output, label)
            polygons = result.polygons() if args.quads else None
            save_mesh(result.vertices, result.faces, path, polygons=polygons)
            bar.write(f"{path}: label {label} ({counts[label]:,} voxels): "
                      f"{_result_line(result)}")
            if polygons is not None:
                bar.write(_quads_line(polygons, path, result.face_quads is None, False))
    finally:
        bar.close()
    return 0


@contextmanager
def _merged_labels_hint():
    """Print a label map read as one mask (``labelmaps.MergedLabelsWarning``) as one
    ``agndc: warning:`` line that names the option meshing each label."""
    from .labelmaps import MergedLabelsWarning

    caught = []
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", MergedLabelsWarning)
            yield
    finally:  # a run that fails still says how its file was read
        for warning in caught:
            if issubclass(warning.category, MergedLabelsWarning):
                print(f"agndc: warning: {warning.message}; --per-label meshes each label on "
                      "its own", file=sys.stderr)
            else:  # not ours: shown as Python would have shown it
                warnings.showwarning(warning.message, warning.category, warning.filename,
                                     warning.lineno)


def _cmd_batch(args) -> int:
    import signal
    import threading

    from .batch import remesh_many, summary

    def interrupt(signum, frame):  # kill (SIGTERM) stops like Ctrl-C: workers ended, temps gone
        raise KeyboardInterrupt

    main_thread = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGTERM, interrupt) if main_thread else None
    try:
        rows = remesh_many(args.inputs, args.output, options_from_args(args), fmt=args.format,
                           workers=args.workers,
                           engine=args.engine or ("dask" if args.scheduler else "local"),
                           scheduler=args.scheduler, overwrite=args.overwrite,
                           progress=not args.no_progress, per_label=args.per_label,
                           labels=args.labels)
    finally:
        if main_thread:
            signal.signal(signal.SIGTERM, previous)
    for row in rows:
        if row["status"] == "failed":
            label = f" label {row['label']}" if row["label"] != "" else ""
            print(f"FAILED {row['input']}{label}: {row['error']}", file=sys.stderr)
    counts = summary(rows)
    print(f"{counts['ok']} done, {counts['skipped']} skipped (up to date), {counts['failed']} "
          f"failed; table: {args.output / 'batch.csv'}")
    return 1 if counts["failed"] else 0


def _cmd_eval(args) -> int:
    from .pipeline import CHECKPOINT_NAMES
    from .study.evaluate import (
        check_shifts,
        evaluate_meshes,
        headroom_lines,
        headroom_table,
        markdown_table,
        method_parts,
        parse_methods,
        require_meshes,
        shift_table,
        summarize_rows,
        write_report,
    )

    methods = parse_methods(args.methods)
    learned_labels = {label for label, base, _ in map(method_parts, methods)
                      if base in CHECKPOINT_NAMES}
    checkpoints = {}
    for item in args.checkpoint:
        method, _, path = item.partition("=")
        if method not in {*CHECKPOINT_NAMES, *learned_labels} or not path:
            raise AGNDCError(f"--checkpoint wants agndc=PATH, undc=PATH or LABEL=PATH for a "
                             f"LABEL=agndc|undc method, got {item!r}")
        checkpoints[method] = Path(path)
    check_shifts(args.shifts)
    meshes = require_meshes(args.folder, args.limit)
    rows = evaluate_meshes(meshes, methods, resolution=args.res, n_samples=args.samples,
                           checkpoints=checkpoints, shifts=args.shifts,
                           normal_filter=args.normal_filter)
    written = write_report(rows, args.out)
    summaries = summarize_rows(rows)
    print(markdown_table(summaries))
    for line in headroom_lines(summaries):  # none unless mc and a ceiling were evaluated
        print(line)
    if len({r["category"] for r in rows}) > 1:
        print(headroom_table(rows))
    if args.shifts > 1:
        print(shift_table(rows))
    print("written: " + ", ".join(str(p) for p in written.values()))
    return 1 if any(r["error"] for r in rows) else 0


def _cmd_demo(args) -> int:
    from .gridio import save_grid, save_mesh
    from .metrics import evaluate
    from .pipeline import remesh_mesh
    from .study.evaluate import markdown_table, summarize_rows
    from .study.shapes import cad_part

    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    vertices, faces = cad_part(args.seed)
    save_mesh(vertices, faces, out / "part.obj")
    # every method a mesh allows, learned ones where their weights are shipped
    methods = [m.name for m in REGISTRY if m.name not in ("sharp", "oracle_binary")
               and (m.weights is None or _has_weights(m.name))]
    rows = []
    for method in methods:
        result = remesh_mesh(vertices, faces, resolution=args.res, method=method, source="part",
                             source_bounds=args.source_bounds)
        save_mesh(result.vertices, result.faces, out / f"part_{method}.obj")
        metrics = evaluate(result.vertices, result.faces, vertices, faces)
        rows.append({"method": method, **metrics, "seconds": result.seconds})
        if method == "mc":
            save_grid(result.grid, out / "part_grid.npz")
    print(f"CAD part (shapes.cad_part({args.seed})) voxelised at {args.res}³, written to {out}/")
    print(markdown_table(summarize_rows(rows)))
    if args.source_bounds:
        print("surfacenets, undc and agndc also used the part's bounding box, as `agndc remesh` "
              "does for a mesh (--no-source-bounds: the grid alone, as marching cubes)")
    missing = [m.name for m in REGISTRY if m.weights and m.name not in methods]
    if missing:
        print(f"note: no shipped weights for {', '.join(missing)}; train with `agndc train`")
    return 0


def _has_weights(method: str) -> bool:
    from .checkpoint import default_checkpoint_path
    from .pipeline import CHECKPOINT_NAMES

    try:
        return Path(default_checkpoint_path(CHECKPOINT_NAMES[method])).exists()
    except AGNDCError:
        return False


if __name__ == "__main__":
    sys.exit(main())
