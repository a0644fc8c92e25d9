"""How the Blender add-on's progress bar moves during long runs: every progress update's time,
fraction and message, the longest wait between two updates and the longest time the bar shows
one percentage.

Each run goes through the add-on's own worker path in bpy (background mode): the jobs are made
on the main thread (``remesh.grid_jobs`` / ``remesh.mesh_jobs``, as the operators' ``execute``
does), then ``remesh.compute_jobs(jobs, settings, progress)`` runs them, which is what the
operators' modal worker thread runs; its progress callback is what the status bar and the
sidebar draw (``operators.RUN``, redrawn every 0.1 s). The status bar's text is shown as the
add-on draws it (``operators.status_text``).

Inputs:
  brain  the folded 197x233x189 mask of ``bench_inference.make_grid("brain")``, saved as .npy
         and imported as a grid file (Import Voxel Grid);
  mesh   a generated CAD part subdivided to at least ``--triangles`` triangles
         (``bench_cancel_stages.dense_part``; 786,432 by default) as an object, remeshed at
         ``--res``.

The first run in the process also imports the core and loads the network (what a user's first
run in a Blender session waits for); ``--warm-up`` runs a small grid first to leave that out.

Usage:
    .venv-bpy/bin/python benchmarks/bench_progress.py [--inputs brain mesh]
        [--methods agndc sharp] [--res 128] [--triangles 750000] [--threads 0] [--trace]
"""

import argparse
import os
import sys
import tempfile
from pathlib import Path

os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="agndc_bench_"))

import bpy  # noqa: E402
import numpy as np  # noqa: E402

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "scripts"))  # the Blender batch script finds the add-on
sys.path.insert(0, str(HERE))  # the other benchmarks' inputs
sys.path.insert(0, str(HERE.parent))  # this checkout's core (the add-on's, in a checkout)
from agndc_batch import find_addon  # noqa: E402

from agndc_core.progress import ProgressLog  # noqa: E402

#: a wait between updates longer than this is a stall a user notices
STALL_SECONDS = 2.0


def load_addon():
    package = find_addon()
    if not hasattr(bpy.types, "VIEW3D_PT_agndc_remesh"):
        package.register()
    import importlib

    return (importlib.import_module(f"{package.__name__}.remesh"),
            importlib.import_module(f"{package.__name__}.operators"),
            importlib.import_module(f"{package.__name__}.mesh_io"))


def load() -> str:
    return ", ".join(f"{x:.2f}" for x in os.getloadavg())


def brain_jobs(remesh, settings, folder: Path):
    from bench_inference import make_grid

    path = folder / "brain.npy"
    if not path.exists():
        np.save(path, make_grid("brain").occupancy)
    return remesh.grid_jobs([path], settings)


def mesh_jobs(remesh, mesh_io, settings, triangles: int):
    from bench_cancel_stages import dense_part

    vertices, faces = dense_part(triangles)
    for obj in list(bpy.data.objects):
        bpy.data.objects.remove(obj)
    obj = bpy.data.objects.new("Part", mesh_io.new_mesh("Part", vertices, faces))
    bpy.context.scene.collection.objects.link(obj)
    return remesh.mesh_jobs([obj], settings), len(faces)


def report(name: str, label: str, recorder: ProgressLog, operators, trace: bool) -> None:
    gap, before, after = recorder.longest_gap()
    flat, percent, first = recorder.longest_flat()
    print(f"\n{name}: {recorder.total:.2f} s, {len(recorder.updates)} updates, "
          f"load average {load()} (1, 5, 15 min)")
    print(f"  longest gap  {gap:6.2f} s ({100 * gap / recorder.total:.0f} % of the run), "
          f"after {before[0]:.2f} s {100 * before[1]:.0f} % '{before[2]}' "
          f"until '{after[2]}'")
    print(f"  longest flat {flat:6.2f} s at {percent} % from {first[0]:.2f} s '{first[2]}'")
    wrong = recorder.backwards()
    if wrong:
        print(f"  the fraction went back {len(wrong)} times, first at {wrong[0][0]:.2f} s")
    shown, previous = [], None
    for t, fraction, message in recorder.updates:
        text = operators.status_text(label, fraction, message)
        stage = message.split(" (")[0].split(" tile")[0]
        if trace or stage != previous:
            shown.append(f"  {t:8.2f} s  {text}")
        previous = stage
    print("  status bar when its stage changes:" if not trace else "  every update:")
    print("\n".join(shown))
    stalls = [(a, b) for a, b in zip(recorder.updates, recorder.updates[1:])
              if b[0] - a[0] > STALL_SECONDS]
    for a, b in stalls:
        print(f"  stall {b[0] - a[0]:.2f} s: '{a[2]}' ({100 * a[1]:.0f} %) -> '{b[2]}'")


def main(argv) -> int:
    argv = argv[argv.index("--") + 1:] if "--" in argv else argv[1:]
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--inputs", nargs="+", default=["brain", "mesh"],
                        choices=("brain", "mesh"))
    parser.add_argument("--methods", nargs="+", default=["agndc", "sharp"],
                        help="mesh input; the brain grid runs the grid methods among them")
    parser.add_argument("--res", type=int, default=128, help="mesh input: voxels, longest side")
    parser.add_argument("--triangles", type=int, default=750_000,
                        help="at least this many (the part's faces split 4-to-1: 786,432)")
    parser.add_argument("--threads", type=int, default=0, help="0: automatic (every core)")
    parser.add_argument("--warm-up", action="store_true",
                        help="load the network before the first measured run")
    parser.add_argument("--trace", action="store_true", help="print every update")
    args = parser.parse_args(argv)
    remesh, operators, mesh_io = load_addon()
    bpy.ops.wm.read_homefile(use_empty=True)
    print(f"bpy {bpy.app.version_string}, {os.cpu_count()} CPUs, load average {load()}")
    folder = Path(tempfile.mkdtemp(prefix="agndc_progress_"))
    if args.warm_up:
        np.save(folder / "small.npy", np.pad(np.ones((6, 6, 6), dtype=bool), 2))
        remesh.compute_jobs(remesh.grid_jobs([folder / "small.npy"],
                                             remesh.Settings(method="agndc")),
                            remesh.Settings(method="agndc"))
    for spec in args.inputs:
        for method in args.methods:
            # the operators' defaults: compare with MC, the distance to the source mesh
            settings = remesh.Settings(method=method, resolution=args.res,
                                       threads=args.threads)
            if spec == "brain":
                if method in remesh.pipeline.MESH_ONLY_METHODS:
                    continue
                jobs = brain_jobs(remesh, settings, folder)
                name = f"brain 197x233x189, {method}"
            else:
                jobs, count = mesh_jobs(remesh, mesh_io, settings, args.triangles)
                name = f"mesh {count:,} triangles at {args.res}, {method}"
            label = remesh.SUFFIXES[method]
            recorder = ProgressLog()
            remesh.compute_jobs(jobs, settings, progress=recorder)
            recorder.finish()
            failed = [job.error for job in jobs if job.error is not None]
            if failed:
                print(f"{name}: failed: {failed}")
            report(name, label, recorder, operators, args.trace)
    return 0


if __name__ == "__main__":
    status = main(sys.argv)
    sys.stdout.flush()
    os._exit(status)  # bpy 4.5 can hang at interpreter exit
