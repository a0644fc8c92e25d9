#!/usr/bin/env python3
"""Build the installable AGNDC Remesher extension zip(s) for Blender 4.2+.

    python build_addon.py                          # all platforms, torch + deps as bundled wheels
    python build_addon.py --platform linux-x64     # one platform (repeatable)
    python build_addon.py --no-wheels              # developer build: code + weights only
    python build_addon.py --no-wheels --legacy     # + a legacy add-on zip (folder inside)

Steps: (1) stage ``build/agndc_remesher/``: ``agndc_blender/*`` at the root, ``agndc_core/``
vendored beside it (without ``training/``; shipped weights included), and a copy of
``blender_manifest.toml`` whose ``platforms``/``wheels`` are filled in (the source manifest is
never rewritten); (2) ``pip download`` the runtime wheels per platform tag into
``build/wheels/<platform>/`` (cached; numpy is left out because Blender ships it);
(3) validate and build with Blender's own ``blender_ext.py`` (stdlib-only, shipped inside the
``bpy`` wheel, or ``--blender`` to use ``blender --command extension``) with
``--split-platforms``; (4) validate every zip.
"""

from __future__ import annotations

import argparse
import glob
import importlib.util
import re
import shutil
import subprocess
import sys
import tempfile
import time
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent
EXTENSION_ID = "agndc_remesher"
PYTHON_VERSION = "3.11"  # Blender 4.2-5.0 embed CPython 3.11

#: manifest platform -> the pip platform tags it accepts. pip does not widen an explicit
#: --platform to older manylinux/macOS versions by itself, so list them.
PLATFORM_TAGS = {
    "linux-x64": ["manylinux_2_28_x86_64",
                  *[f"manylinux_2_{minor}_x86_64" for minor in range(27, 16, -1)],
                  "manylinux2014_x86_64"],
    "windows-x64": ["win_amd64"],
    "macos-arm64": [*[f"macosx_{major}_0_arm64" for major in range(14, 10, -1)],
                    *[f"macosx_{major}_0_universal2" for major in range(14, 10, -1)],
                    *[f"macosx_10_{minor}_universal2" for minor in range(15, 8, -1)]],
}
#: Python ABIs the wheels may target (CPython 3.11 extension modules, stable ABI, pure)
ABIS = ["cp311", "abi3", "none"]

#: what agndc_core imports at run time in Blender (torch and the libraries imported by the
#: remesh, grid-IO and metrics paths); numpy is Blender's own. manifold3d (training shapes only),
#: tqdm (CLI only), rtree and matplotlib are not needed inside Blender.
RUNTIME_REQUIREMENTS = [
    "torch==2.13.0",
    "scipy>=1.11",
    "scikit-image>=0.22",
    "trimesh>=4.0",
    "nibabel>=5.0",
    "safetensors>=0.4",
]
#: resolution constraints: Blender 4.2-5.0 ship numpy 1.x, so pick wheels that support it
CONSTRAINTS = ["numpy>=1.24,<2"]
#: wheels dropped after download (Blender provides them)
PROVIDED_BY_BLENDER = ("numpy",)

EXCLUDE_PATTERNS = shutil.ignore_patterns("__pycache__", "*.pyc", ".*")


def main(argv=None) -> int:
    args = parse_args(argv)
    platforms = args.platform or list(PLATFORM_TAGS)
    start = time.perf_counter()
    stage = stage_sources(args.build_dir / EXTENSION_ID)
    wheels: list[Path] = []
    if not args.no_wheels:
        for platform in platforms:
            wheels += download_wheels(platform, args.build_dir / "wheels" / platform)
        copy_wheels(wheels, stage / "wheels")
    names = sorted({wheel.name for wheel in wheels})  # pure wheels appear once per platform
    write_manifest(stage / "blender_manifest.toml", platforms, [f"./wheels/{n}" for n in names])
    args.out.mkdir(parents=True, exist_ok=True)
    for old in args.out.glob(f"{EXTENSION_ID}-*.zip"):
        old.unlink()
    cli = ExtensionCLI(args.blender)
    cli.run("validate", str(stage))
    build_args = ["build", "--source-dir", str(stage), "--output-dir", str(args.out)]
    cli.run(*build_args, *([] if args.no_wheels else ["--split-platforms"]))
    zips = sorted(args.out.glob(f"{EXTENSION_ID}-*.zip"))
    if not zips:
        raise SystemExit("build produced no zip")
    for path in zips:
        cli.run("validate", str(path))
        print(f"{path}  {path.stat().st_size / 1e6:.1f} MB")
    if args.legacy:
        legacy = args.out / f"{EXTENSION_ID}-{_manifest_version()}-legacy.zip"
        shutil.make_archive(str(legacy)[: -len(".zip")], "zip", stage.parent, stage.name)
        print(f"{legacy}  {legacy.stat().st_size / 1e6:.1f} MB (legacy add-on)")
    print(f"built {len(zips)} zip(s) in {time.perf_counter() - start:.1f} s")
    return 0


def parse_args(argv):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--platform", action="append", choices=sorted(PLATFORM_TAGS),
                        help="build for this platform only (repeatable; default: all)")
    parser.add_argument("--no-wheels", action="store_true",
                        help="developer build without bundled wheels (torch etc. must already "
                             "be importable in Blender); one zip for all platforms")
    parser.add_argument("--legacy", action="store_true",
                        help="also write <id>-<version>-legacy.zip, the same staged folder "
                             "zipped under its own name, for Install legacy Add-on (no wheels: "
                             "the core's dependencies must come from Blender's Python)")
    parser.add_argument("--out", type=Path, default=ROOT / "dist", help="output folder")
    parser.add_argument("--build-dir", type=Path, default=ROOT / "build",
                        help="staging folder and wheel cache")
    parser.add_argument("--blender", help="a Blender 4.2+ executable to build and validate "
                                          "with (default: blender_ext.py from the bpy module)")
    return parser.parse_args(argv)


def _manifest_version() -> str:
    text = (ROOT / "blender_manifest.toml").read_text(encoding="utf-8")
    return re.search(r'(?m)^version\s*=\s*"([^"]+)"', text).group(1)


def stage_sources(stage: Path) -> Path:
    """Copy the add-on, the vendored core and its shipped weights into a clean staging folder."""
    if stage.exists():
        shutil.rmtree(stage)
    shutil.copytree(ROOT / "agndc_blender", stage, ignore=EXCLUDE_PATTERNS)
    shutil.copytree(ROOT / "agndc_core", stage / "agndc_core",
                    ignore=shutil.ignore_patterns("__pycache__", "*.pyc", ".*", "training"))
    return stage


def write_manifest(path: Path, platforms: list[str], wheels: list[str]) -> None:
    """The staged manifest: the source one with ``platforms`` narrowed and ``wheels`` added.

    Top-level keys must precede the first ``[table]`` in TOML, so ``wheels`` goes just before it.
    """
    text = (ROOT / "blender_manifest.toml").read_text(encoding="utf-8")
    listed = ", ".join(f'"{p}"' for p in platforms)
    text, count = re.subn(r"(?m)^platforms\s*=.*$", f"platforms = [{listed}]", text)
    if count != 1:
        raise SystemExit("blender_manifest.toml: expected exactly one 'platforms = [...]' line")
    if wheels:
        lines = ",\n".join(f'  "{w}"' for w in wheels)
        block = f"wheels = [\n{lines},\n]\n\n"
        first_table = re.search(r"(?m)^\[", text)
        cut = first_table.start() if first_table else len(text)
        text = text[:cut] + block + text[cut:]
    path.write_text(text, encoding="utf-8")


def download_wheels(platform: str, dest: Path) -> list[Path]:
    """Runtime wheels (with dependencies, minus Blender's own) for one platform, cached in dest.

    pip evaluates environment markers for the machine it runs on, not for ``--platform``, so on
    Linux it would ask for torch's CUDA wheels even for Windows. torch is therefore fetched
    without dependencies, and its ``Requires-Dist`` is evaluated for the target platform here.
    """
    dest.mkdir(parents=True, exist_ok=True)
    torch_req, others = RUNTIME_REQUIREMENTS[0], RUNTIME_REQUIREMENTS[1:]
    print(f"[{platform}] pip download {' '.join(RUNTIME_REQUIREMENTS)}", flush=True)
    _pip_download(platform, dest, [torch_req], deps=False)
    (torch_wheel,) = [w for w in dest.glob("torch-*.whl")
                      if _version(w).split("+")[0] == torch_req.split("==")[1]]
    _pip_download(platform, dest, others + _requirements_for(torch_wheel, platform), deps=True)
    wheels = [w for w in sorted(dest.glob("*.whl"))
              if _project(w) not in PROVIDED_BY_BLENDER and _fits(w, platform)]
    print(f"[{platform}] {len(wheels)} wheels, "
          f"{sum(w.stat().st_size for w in wheels) / 1e6:.1f} MB", flush=True)
    return wheels


def _pip_download(platform: str, dest: Path, requirements: list[str], deps: bool) -> None:
    with tempfile.NamedTemporaryFile("w", suffix=".txt", delete=False) as handle:
        handle.write("\n".join(CONSTRAINTS) + "\n")
        constraints = handle.name
    command = [sys.executable, "-m", "pip", "download", "--disable-pip-version-check",
               "--only-binary=:all:", "--python-version", PYTHON_VERSION,
               "--implementation", "cp", "--dest", str(dest), "-c", constraints]
    command += [] if deps else ["--no-deps"]
    for tag in PLATFORM_TAGS[platform]:
        command += ["--platform", tag]
    for abi in ABIS:
        command += ["--abi", abi]
    try:
        subprocess.run(command + requirements, check=True)
    finally:
        Path(constraints).unlink()


#: environment-marker values of each target platform (PEP 508)
MARKER_ENVIRONMENTS = {
    "linux-x64": {"sys_platform": "linux", "platform_system": "Linux",
                  "platform_machine": "x86_64", "os_name": "posix"},
    "windows-x64": {"sys_platform": "win32", "platform_system": "Windows",
                    "platform_machine": "AMD64", "os_name": "nt"},
    "macos-arm64": {"sys_platform": "darwin", "platform_system": "Darwin",
                    "platform_machine": "arm64", "os_name": "posix"},
}


def _requirements_for(wheel: Path, platform: str) -> list[str]:
    """The wheel's Requires-Dist that apply on ``platform`` with CPython 3.11 (no extras)."""
    try:
        from packaging.requirements import Requirement
    except ImportError:  # pip always vendors it
        from pip._vendor.packaging.requirements import Requirement
    environment = {"python_version": PYTHON_VERSION, "python_full_version": f"{PYTHON_VERSION}.0",
                   "implementation_name": "cpython", "platform_python_implementation": "CPython",
                   "extra": "", **MARKER_ENVIRONMENTS[platform]}
    with zipfile.ZipFile(wheel) as archive:
        (metadata,) = [n for n in archive.namelist() if n.endswith(".dist-info/METADATA")]
        lines = archive.read(metadata).decode("utf-8").splitlines()
    requirements = []
    for line in lines:
        if line.startswith("Requires-Dist:"):
            requirement = Requirement(line.split(":", 1)[1].strip())
            if requirement.marker is None or requirement.marker.evaluate(environment):
                requirement.marker = None
                requirements.append(str(requirement))
    return requirements


def _version(wheel: Path) -> str:
    return wheel.name.split("-")[1]


def _fits(wheel: Path, platform: str) -> bool:
    """Pure wheels and wheels tagged for ``platform`` (the cache may hold older downloads)."""
    tags = wheel.name[:-len(".whl")].split("-")[-1].split(".")
    return any(tag == "any" or tag in PLATFORM_TAGS[platform] for tag in tags)


def _project(wheel: Path) -> str:
    return wheel.name.split("-")[0].lower().replace("_", "-")


def copy_wheels(wheels: list[Path], dest: Path) -> None:
    dest.mkdir(parents=True, exist_ok=True)
    for wheel in wheels:
        shutil.copy2(wheel, dest / wheel.name)


class ExtensionCLI:
    """Blender's extension command line: ``blender --command extension ...`` or, without a
    Blender executable, the stdlib-only ``blender_ext.py`` shipped inside the bpy wheel."""

    def __init__(self, blender: str | None):
        if blender:
            self.prefix = [blender, "--factory-startup", "--command", "extension"]
            self.tags = []  # Blender passes its own list of valid tags
            return
        script, tags = _find_blender_ext()
        self.prefix = [sys.executable, str(script)]
        self.tags = ["--valid-tags", str(tags)] if tags else []

    def run(self, command: str, *args: str) -> None:
        extra = self.tags if command in ("build", "validate") else []
        subprocess.run([*self.prefix, command, *args, *extra], check=True)


def _find_blender_ext() -> tuple[Path, Path | None]:
    """blender_ext.py (and the tags list Blender validates against) inside the bpy package."""
    spec = importlib.util.find_spec("bpy")
    if spec is None or not spec.submodule_search_locations:
        raise SystemExit("bpy is not installed in this Python: run scripts/setup_bpy_env.sh and "
                         "use .venv-bpy/bin/python, or pass --blender /path/to/blender")
    base = Path(next(iter(spec.submodule_search_locations)))
    found = glob.glob(str(base / "*" / "scripts/addons_core/bl_pkg/cli/blender_ext.py"))
    if not found:
        raise SystemExit(f"blender_ext.py not found under {base}")
    script = Path(sorted(found)[-1])
    tags = script.parents[3] / "modules/_bpy_internal/extensions/tags.py"
    return script, tags if tags.is_file() else None


if __name__ == "__main__":
    sys.exit(main())
