"""Time "Remesh with AGNDC" against Blender's own Voxel Remesh on a generated CAD part.

    .venv-bpy/bin/python benchmarks/bench_blender.py [--res 64 128] [--methods mc agndc]
        [--seed 7] [--repeat 3] [--install-zip dist/agndc_remesher-0.1.0-linux_x64.zip]
    blender -b --factory-startup --python-exit-code 1 -P benchmarks/bench_blender.py -- ...

For each resolution and method it runs the operator (wall time of ``bpy.ops.object.agndc_remesh``,
including the Chamfer distance in its report) and ``remesh_object`` without the distance
(voxelise + reconstruct + new object), then searches the voxel size at which
``bpy.ops.object.voxel_remesh`` gives a similar triangle count and times that, all in the same
process. Prints a markdown table; times are medians of --repeat runs after a warm-up.
With --install-zip the extension zip is installed into a fresh user folder first (timed).
"""

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="agndc_bench_"))

import bpy  # noqa: E402

# the Blender batch script (scripts/agndc_batch.py) finds the installed extension
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))
from agndc_batch import find_addon  # noqa: E402


def parse_args(argv):
    argv = argv[argv.index("--") + 1:] if "--" in argv else argv[1:]
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--res", type=int, nargs="+", default=[64, 128])
    parser.add_argument("--methods", nargs="+", default=None,
                        help="default: mc, plus agndc when its weights are shipped")
    parser.add_argument("--seed", type=int, default=7,
                        help="cad_part seed (first CAD seed at or after it)")
    parser.add_argument("--size", type=float, default=2.0, help="longest side of the part")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--install-zip", type=Path, help="install this extension zip first")
    parser.add_argument("--checkpoint", type=Path,
                        help="weights for agndc instead of the shipped ones (an untrained "
                             "checkpoint times the same network); needs the add-on installed "
                             "(--install-zip) so its preferences exist")
    return parser.parse_args(argv)


def install(zip_path: Path) -> float:
    start = time.perf_counter()
    result = bpy.ops.extensions.package_install_files(filepath=str(zip_path.resolve()),
                                                      repo="user_default",
                                                      enable_on_install=True)
    seconds = time.perf_counter() - start
    if result != {"FINISHED"}:
        raise SystemExit(f"installing {zip_path} failed: {result}")
    return seconds


def load_addon():
    """The add-on package, registered (the operator must exist)."""
    package = find_addon()
    if not hasattr(bpy.types, "VIEW3D_PT_agndc_remesh"):
        package.register()
    import importlib

    return (importlib.import_module(f"{package.__name__}.remesh"),
            importlib.import_module(f"{package.__name__}.mesh_io"))


def median_time(func, repeat: int):
    times, value = [], None
    for _ in range(repeat):
        start = time.perf_counter()
        value = func()
        times.append(time.perf_counter() - start)
    return statistics.median(times), value


def triangles(obj) -> int:
    obj.data.calc_loop_triangles()
    return len(obj.data.loop_triangles)


def clear_results(keep):
    for obj in list(bpy.data.objects):
        if obj is not keep:
            mesh = obj.data
            bpy.data.objects.remove(obj)
            if mesh is not None and mesh.users == 0:
                bpy.data.meshes.remove(mesh)


def select_only(obj):
    for other in bpy.context.selected_objects:
        other.select_set(False)
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj


def run_operator(source, res, method):
    select_only(source)
    result = bpy.ops.object.agndc_remesh(resolution=res, method=method, compare_mc=False)
    assert result == {"FINISHED"}, result
    obj = bpy.context.view_layer.objects.active
    count = triangles(obj)
    clear_results(source)
    return count


def voxel_remesh(source, voxel_size):
    """Blender's Voxel Remesh of a copy of ``source`` -> triangle count (copy removed)."""
    copy = source.copy()
    copy.data = source.data.copy()
    bpy.context.scene.collection.objects.link(copy)
    select_only(copy)
    copy.data.remesh_voxel_size = voxel_size
    assert bpy.ops.object.voxel_remesh() == {"FINISHED"}
    count = triangles(copy)
    clear_results(source)
    return count


def matching_voxel_size(source, target: int, start: float) -> tuple[float, int]:
    """Voxel size whose Voxel Remesh triangle count is closest to ``target`` (faces ~ 1/size^2)."""
    best, size = None, start
    for _ in range(4):
        count = voxel_remesh(source, size)
        if best is None or abs(count - target) < abs(best[1] - target):
            best = (size, count)
        size *= (count / target) ** 0.5
    return best


def main(argv) -> int:
    args = parse_args(argv)
    install_seconds = install(args.install_zip) if args.install_zip else None
    remesh, mesh_io = load_addon()
    from agndc_core.study.shapes import cad_part

    bpy.ops.wm.read_homefile(use_empty=True)
    vertices, faces = cad_part(args.seed)
    vertices = vertices * args.size
    source = bpy.data.objects.new("Part", mesh_io.new_mesh("Part", vertices, faces))
    bpy.context.scene.collection.objects.link(source)
    if args.checkpoint:
        addon = next((a for name, a in bpy.context.preferences.addons.items()
                      if name.endswith("agndc_remesher")), None)
        if addon is None:
            raise SystemExit("--checkpoint needs the installed add-on: pass --install-zip")
        addon.preferences.checkpoint = str(args.checkpoint.resolve())
    has_weights = args.checkpoint or remesh.checkpoint_path("agndc").is_file()
    methods = args.methods or ["mc"] + (["agndc"] if has_weights else [])
    run_operator(source, 16, "mc")  # warm-up: imports scipy/skimage/torch
    if "agndc" in methods:
        run_operator(source, 16, "agndc")
    rows = []
    for res in args.res:
        for method in methods:
            op_s, count = median_time(lambda r=res, m=method: run_operator(source, r, m),
                                      args.repeat)
            settings = remesh.Settings(resolution=res, method=method, compare_mc=False,
                                       distance=False,
                                       checkpoint=str(args.checkpoint) if args.checkpoint else None)

            def api(settings=settings):
                report = remesh.remesh_object(source, settings)
                clear_results(source)
                return report

            api_s, _ = median_time(api, args.repeat)
            size, voxel_count = matching_voxel_size(source, count, args.size / res)
            voxel_s, _ = median_time(lambda s=size: voxel_remesh(source, s), args.repeat)
            rows.append((res, method, count, op_s, api_s, size, voxel_count, voxel_s))
    print(f"\nbpy {bpy.app.version_string}, part: cad_part({args.seed}) x {args.size} "
          f"({len(faces):,} triangles), {os.cpu_count()} CPUs, median of {args.repeat}")
    if install_seconds is not None:
        size_mb = args.install_zip.stat().st_size / 1e6
        print(f"install {args.install_zip.name} ({size_mb:.1f} MB): {install_seconds:.1f} s")
    print("\n| res | method | triangles | operator s | remesh only s | voxel size | "
          "Voxel Remesh triangles | Voxel Remesh s | operator / voxel |")
    print("|---|---|---|---|---|---|---|---|---|")
    for res, method, count, op_s, api_s, size, voxel_count, voxel_s in rows:
        print(f"| {res}³ | {method} | {count:,} | {op_s:.3f} | {api_s:.3f} | {size:.4f} | "
              f"{voxel_count:,} | {voxel_s:.3f} | {op_s / voxel_s:.1f}× |")
    return 0


if __name__ == "__main__":
    status = main(sys.argv)
    sys.stdout.flush()
    os._exit(status)  # bpy 4.5 can hang at interpreter exit
