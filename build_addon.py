#!/usr/bin/env python3
"""Build the installable AGNDC Remesher extension zip(s) for Blender 4.2+.

    python build_addon.py                          # all platforms, Python 3.11 and 3.13 wheels
    python build_addon.py --platform linux-x64     # one platform (repeatable)
    python build_addon.py --python 3.11            # Blender 4.2-5.0 only (3.13: Blender 5.1+)
    python build_addon.py --find-links DIR         # offline: every wheel from local folders
    python build_addon.py --no-wheels              # developer build: code + weights only
    python build_addon.py --no-wheels --legacy     # + a legacy add-on zip (folder inside)

Steps: (1) stage ``build/agndc_remesher/``: ``agndc_blender/*`` at the root and the product part
of ``agndc_core/`` vendored beside it (``PRODUCT_MODULES``: I/O, voxeliser, the numpy inference
runtime, contouring, filters; no training, evaluation, research or torch code) with the shipped
weights, and a copy of ``blender_manifest.toml`` whose ``platforms``/``wheels`` are filled in
(the source manifest is never rewritten); (2) ``pip download`` the runtime wheels per platform
and Python into ``build/wheels/<platform>/<cpXY>/`` (numpy is left out because Blender ships it;
torch and CUDA packages are refused: the networks run in numpy); (3) validate and build with
Blender's own ``blender_ext.py`` (stdlib-only, shipped inside the ``bpy`` wheel, or
``--blender`` to use ``blender --command extension``) with ``--split-platforms``; (4) validate
every zip.

Wheel sources: pip's configured index, or, with ``--find-links``, the given folders only
(``--no-index``: nothing is fetched from the network).

Two Pythons. Blender 4.2-5.0 embed CPython 3.11, Blender 5.1+ CPython 3.13. One zip carries
both wheel sets: at install Blender keeps only the wheels whose platform and Python tags match
it (``bl_pkg/bl_extension_ops.py::_extensions_wheel_filter_for_this_system``), then, per
project, the highest version (``_bpy_internal/extensions/wheel_manager.py::
wheel_list_deduplicate_as_skip_set``); ``python_compatible`` mirrors the filter and
``merge_wheel_sets`` the deduplication.
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
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parent
EXTENSION_ID = "agndc_remesher"

#: target Python -> the Blender releases that embed it
PYTHONS = {"3.11": "Blender 4.2-5.0", "3.13": "Blender 5.1+"}
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

#: what agndc_core imports at run time in Blender; numpy is Blender's own. scipy: distance
#: transforms, sparse components, KD-trees; scikit-image: marching cubes; trimesh and rtree:
#: Taubin smoothing and sharp mode's closest-point query; nibabel: NIfTI grids; threadpoolctl:
#: one BLAS thread per inference worker; manifold3d: Low Poly's decimation (decimate.py, ~1 MB
#: wheels). No torch: the networks run in numpy.
RUNTIME_REQUIREMENTS = [
    "scipy>=1.11",
    "scikit-image>=0.22",
    "trimesh>=4.0",
    "rtree>=1.0",
    "nibabel>=5.0",
    "threadpoolctl>=3.1",
    "manifold3d>=3.0",
]
#: resolution constraints per Python: pick wheels that work with the numpy Blender ships
#: (Blender 4.2-5.0: numpy 1.x, bpy 4.5/5.0 pin numpy>=1.26,<2; bpy 5.2.3 (cp313) pins
#: numpy>=2.2,<3)
CONSTRAINTS = {"3.11": ["numpy>=1.24,<2"], "3.13": ["numpy>=2.2,<3"]}
#: wheels dropped after download: Blender provides numpy; scikit-image's image I/O and graph
#: dependencies are never imported by ``skimage.measure.marching_cubes`` (the add-on's only use;
#: the Blender tests run against the installed zip without them)
NOT_BUNDLED = ("numpy", "pillow", "imageio", "tifffile", "networkx")
#: projects that must never be in the zip (the extension runs on the CPU without torch)
REFUSED = re.compile(r"^(torch|nvidia-.*|cuda-.*|triton|pytorch-triton.*)$")
#: the product part of agndc_core (vendored into the extension); everything else in it is the
#: training and research wing. nn/ contributes only its torch-free config and layout.
PRODUCT_MODULES = (
    "__init__.py", "py.typed", "errors.py", "grid.py", "gridio.py", "voxelize.py", "plan.py",
    "labels.py", "labelmaps.py", "methods.py", "options.py",
    "surfacenets.py", "contour.py", "flatpatches.py", "normalfilter.py", "mc.py", "metrics.py",
    "quads.py",
    "pipeline.py", "progress.py", "inference.py", "checkpoint.py", "tolerances.py", "batch.py",
    "batch_job.py", "batch_dask.py", "colors.py", "decimate.py", "meshcheck.py", "formats",
    "runtime", "weights",
    "nn/__init__.py", "nn/config.py", "nn/layout.py",
)

EXCLUDE_PATTERNS = shutil.ignore_patterns("__pycache__", "*.pyc", ".*")


class BuildError(SystemExit):
    """A build that cannot go on; the message says why and what to do (exit status 1)."""

    def __init__(self, message: str):
        super().__init__(f"build_addon.py: error: {message}")


class UnresolvedError(BuildError):
    """pip found no wheel set for one platform and Python (``requirements``: what it was asked)."""

    def __init__(self, message: str, requirements=()):
        super().__init__(message)
        self.requirements = list(requirements)


@dataclass
class WheelSources:
    """Where wheels come from: pip's configured indexes, or only the ``find_links`` folders."""

    find_links: list[Path] = field(default_factory=list)

    def pip_args(self) -> list[str]:
        links = [arg for d in self.find_links for arg in ("--find-links", str(d))]
        return ["--no-index", *links] if links else []


def main(argv=None) -> int:
    args = parse_args(argv)
    platforms = args.platform or list(PLATFORM_TAGS)
    start = time.perf_counter()
    stage = stage_sources(args.build_dir / EXTENSION_ID)
    wheels: list[Path] = []
    if not args.no_wheels:
        sources = WheelSources(find_links=args.find_links)
        for platform in platforms:
            per_python: dict[str, list[Path]] = {}
            for python in args.python:
                per_python[python] = download_consistent(
                    platform, python, sources, args.build_dir / "wheels" / platform, per_python)
            wheels += merge_wheel_sets(per_python, platform)
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
        raise BuildError("the build produced no zip")
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
    parser.add_argument("--python", type=parse_pythons, default=list(PYTHONS),
                        help="comma-separated target Pythons (default: 3.11,3.13; 3.11 = "
                             "Blender 4.2-5.0, 3.13 = Blender 5.1+)")
    parser.add_argument("--find-links", action="append", type=Path, default=[], metavar="DIR",
                        help="take every wheel from this folder (repeatable): an offline build, "
                             "pip's index is not used")
    parser.add_argument("--no-wheels", action="store_true",
                        help="developer build without bundled wheels (scipy etc. must already "
                             "be importable in Blender); one zip for all platforms")
    parser.add_argument("--legacy", action="store_true",
                        help="also write <id>-<version>-legacy.zip, the same staged folder "
                             "zipped under its own name, for Install legacy Add-on (no wheels: "
                             "the core's dependencies must come from Blender's Python)")
    parser.add_argument("--out", type=Path, default=ROOT / "dist", help="output folder")
    parser.add_argument("--build-dir", type=Path, default=ROOT / "build",
                        help="staging folder and wheel folders")
    parser.add_argument("--blender", help="a Blender 4.2+ executable to build and validate "
                                          "with (default: blender_ext.py from the bpy module)")
    args = parser.parse_args(argv)
    missing = [str(d) for d in args.find_links if not d.is_dir()]
    if missing:
        parser.error(f"--find-links: not a folder: {', '.join(missing)}")
    return args


def parse_pythons(text: str) -> list[str]:
    """``"3.11,3.13"`` -> ["3.11", "3.13"]; only Pythons that some Blender embeds."""
    pythons = [p.strip() for p in text.split(",") if p.strip()]
    unknown = [p for p in pythons if p not in PYTHONS]
    if not pythons or unknown:
        raise argparse.ArgumentTypeError(
            f"unsupported Python {', '.join(unknown) or text!r}; choose from "
            + ", ".join(f"{p} ({b})" for p, b in PYTHONS.items()))
    return list(dict.fromkeys(pythons))


def _manifest_version() -> str:
    text = (ROOT / "blender_manifest.toml").read_text(encoding="utf-8")
    return re.search(r'(?m)^version\s*=\s*"([^"]+)"', text).group(1)


def stage_sources(stage: Path) -> Path:
    """Copy the add-on, the product part of the core and its shipped weights into a clean
    staging folder."""
    if stage.exists():
        shutil.rmtree(stage)
    shutil.copytree(ROOT / "agndc_blender", stage, ignore=EXCLUDE_PATTERNS)
    # the Help button's guide, readable offline (agndc_blender/operators.py USER_GUIDES)
    shutil.copy2(ROOT / "docs" / "blender.md", stage / "user_guide.md")
    for name in PRODUCT_MODULES:
        source, dest = ROOT / "agndc_core" / name, stage / "agndc_core" / name
        dest.parent.mkdir(parents=True, exist_ok=True)
        if source.is_dir():
            shutil.copytree(source, dest, ignore=EXCLUDE_PATTERNS)
        else:
            shutil.copy2(source, dest)
    return stage


def write_manifest(path: Path, platforms: list[str], wheels: list[str]) -> None:
    """The staged manifest: the source one with ``platforms`` narrowed and ``wheels`` added.

    Top-level keys must precede the first ``[table]`` in TOML, so ``wheels`` goes just before it.
    """
    text = (ROOT / "blender_manifest.toml").read_text(encoding="utf-8")
    listed = ", ".join(f'"{p}"' for p in platforms)
    text, count = re.subn(r"(?m)^platforms\s*=.*$", f"platforms = [{listed}]", text)
    if count != 1:
        raise BuildError("blender_manifest.toml: expected exactly one 'platforms = [...]' line")
    if wheels:
        lines = ",\n".join(f'  "{w}"' for w in wheels)
        block = f"wheels = [\n{lines},\n]\n\n"
        first_table = re.search(r"(?m)^\[", text)
        cut = first_table.start() if first_table else len(text)
        text = text[:cut] + block + text[cut:]
    path.write_text(text, encoding="utf-8")


# -- downloading ------------------------------------------------------------------------------

def download_consistent(platform: str, python: str, sources: WheelSources, cache: Path,
                        earlier: dict[str, list[Path]]) -> list[Path]:
    """``download_wheels`` with the wheels that the earlier Pythons' sets share with this one
    (pure and stable-ABI wheels) pinned to the same versions, so one copy serves every Blender
    (Blender would install only the highest version of each anyway). Falls back to an unpinned
    resolution when the pins cannot be met; ``merge_wheel_sets`` then checks the outcome."""
    pins = sorted({f"{_project(w)}=={_version(w)}" for wheels in earlier.values()
                   for w in wheels if python_compatible(w.name, python)})
    if not pins:
        return download_wheels(platform, python, sources, cache)
    try:
        return download_wheels(platform, python, sources, cache, pins=pins)
    except UnresolvedError:
        print(f"[{platform} {python}] the versions shared with Python "
              f"{', '.join(earlier)} do not resolve; resolving again without them", flush=True)
        return download_wheels(platform, python, sources, cache)


def download_wheels(platform: str, python: str, sources: WheelSources, cache: Path, *,
                    pins=()) -> list[Path]:
    """Runtime wheels (with dependencies, minus ``NOT_BUNDLED``) for one platform and Python.

    The folder is emptied first, so only this run's resolution is bundled (pip's own cache
    keeps repeated builds from downloading again). ``pins`` are extra constraints
    (``project==version``).
    """
    dest = cache / f"cp{python.replace('.', '')}"
    if dest.exists():
        shutil.rmtree(dest)
    dest.mkdir(parents=True)
    print(f"[{platform} {python}] pip download {' '.join(RUNTIME_REQUIREMENTS)}", flush=True)
    _pip_download(platform, python, dest, RUNTIME_REQUIREMENTS, sources.pip_args(),
                  [*CONSTRAINTS[python], *pins])
    wheels = [w for w in sorted(dest.glob("*.whl")) if _project(w) not in NOT_BUNDLED]
    check_no_torch(wheels, platform, python)
    misfits = [w.name for w in wheels if not fits(w.name, platform, python)]
    if misfits:
        raise BuildError(f"{platform}, Python {python}: pip returned wheels Blender would not "
                         f"install there: {', '.join(misfits)}")
    print(f"[{platform} {python}] {len(wheels)} wheels, "
          f"{sum(w.stat().st_size for w in wheels) / 1e6:.1f} MB", flush=True)
    return wheels


def pip_download_command(platform: str, python: str, dest: Path, requirements: list[str],
                         source_args: list[str], *, constraints: Path) -> list[str]:
    """The ``pip download`` command line for one platform and target Python."""
    command = [sys.executable, "-m", "pip", "download", "--disable-pip-version-check",
               "--only-binary=:all:", "--python-version", python, "--implementation", "cp",
               "--dest", str(dest), "-c", str(constraints), *source_args]
    for tag in PLATFORM_TAGS[platform]:
        command += ["--platform", tag]
    for abi in abis(python):
        command += ["--abi", abi]
    return command + requirements


def abis(python: str) -> list[str]:
    """ABI tags a CPython ``python`` accepts: its own extension ABI, the stable ABI, pure."""
    return [f"cp{python.replace('.', '')}", "abi3", "none"]


def _pip_download(platform: str, python: str, dest: Path, requirements: list[str],
                  source_args: list[str], constraint_lines: list[str]) -> None:
    with tempfile.TemporaryDirectory() as folder:
        constraints = Path(folder) / "constraints.txt"
        constraints.write_text("\n".join(constraint_lines) + "\n")
        command = pip_download_command(platform, python, dest, requirements, source_args,
                                       constraints=constraints)
        result = subprocess.run(command, stderr=subprocess.PIPE, text=True)
    sys.stderr.write(result.stderr)
    if result.returncode != 0:
        raise UnresolvedError(unresolved_message(platform, python, requirements, result.stderr),
                              requirements)


def unresolved_message(platform: str, python: str, requirements: list[str], stderr: str) -> str:
    """Why a wheel set could not be resolved, and the two ways out."""
    reason = [line for line in stderr.splitlines() if line.startswith("ERROR")][:2]
    return (f"cannot resolve the wheels for {platform}, Python {python} ({PYTHONS[python]}): "
            f"{' '.join(requirements)}. pip: {' / '.join(reason) or 'see above'}. "
            f"Build without that Python (e.g. --python 3.11) or pass a folder that holds the "
            f"missing wheels with --find-links DIR.")


# -- checks ------------------------------------------------------------------------------------

def check_no_torch(wheels, platform: str, python: str) -> None:
    """Refuse torch and CUDA packages: the extension runs its networks in numpy."""
    refused = [Path(w).name for w in wheels if REFUSED.match(_project(w))]
    if refused:
        raise BuildError(f"{platform}, Python {python}: refusing to bundle {', '.join(refused)}: "
                         "the extension runs its networks without torch (agndc_core/runtime); "
                         "a dependency that pulls torch in must not be a runtime requirement")


def _wheel_tags(name: str) -> tuple[list[str], list[str], list[str]]:
    """(python tags, abi tags, platform tags) of a wheel file name (compressed sets split)."""
    python_tag, abi_tag, platform_tag = name[: -len(".whl")].split("-")[-3:]
    return python_tag.split("."), abi_tag.split("."), platform_tag.split(".")


def python_compatible(name: str, python: str) -> bool:
    """Would Blender running CPython ``python`` install this wheel? Blender's rule
    (``_extensions_wheel_filter_for_this_system``): a ``cpXY``/``pyXY`` tag must equal the
    running version, ``py3``/``cp3`` matches any 3.x, and a stable-ABI (``abi3``) wheel of an
    older 3.x also fits."""
    current = tuple(int(x) for x in python.split("."))
    python_tags, abi_tags, _ = _wheel_tags(name)
    stable = any(a.startswith("abi") and a[3:].isdigit() and int(a[3:]) == current[0]
                 for a in abi_tags)
    for tag in python_tags:
        match = re.fullmatch(r"(?:cp|py)(\d)(\d*)", tag)
        if match is None:
            continue
        major, minor = int(match.group(1)), match.group(2)
        if not minor and major == current[0]:
            return True
        if minor and ((major, int(minor)) == current
                      or (stable and major == current[0] and int(minor) <= current[1])):
            return True
    return False


def fits(name: str, platform: str, python: str) -> bool:
    """Does a wheel file name match the platform's tags and the Python (as Blender judges)?"""
    platform_tags = _wheel_tags(name)[2]
    on_platform = any(t == "any" or t in PLATFORM_TAGS[platform] for t in platform_tags)
    return on_platform and python_compatible(name, python)


def merge_wheel_sets(per_python: dict[str, list[Path]], platform: str) -> list[Path]:
    """One platform's wheels for every target Python, as Blender will pick from them.

    Blender installs, per project, the highest version among the wheels that fit its Python.
    Where two resolutions chose different versions of a wheel that fits both Pythons (a pure
    or abi3 wheel), the higher one wins everywhere: it is kept only if its Requires-Python
    admits every Python it would be installed for; the shadowed lower one is dropped.
    """
    SpecifierSet, Version = _packaging("specifiers").SpecifierSet, _packaging("version").Version
    union = {w.name: w for wheels in per_python.values() for w in wheels}
    chosen: dict[str, Path] = {}
    for python in per_python:
        by_project: dict[str, list[Path]] = {}
        for wheel in union.values():
            if fits(wheel.name, platform, python):
                by_project.setdefault(_project(wheel), []).append(wheel)
        for candidates in by_project.values():
            best = max(candidates, key=lambda w: Version(_version(w)))
            requires = requires_python(best)
            if requires and not SpecifierSet(requires).contains(f"{python}.0"):
                raise BuildError(
                    f"{platform}: {best.name} (resolved for another Python) would be "
                    f"installed by {PYTHONS[python]} (Python {python}) but requires Python "
                    f"{requires}; build the Pythons separately (--python {python}).")
            chosen[best.name] = best
    return sorted(chosen.values(), key=lambda w: w.name)


def requires_python(wheel: Path) -> str:
    """The wheel's ``Requires-Python`` (empty when absent or the file does not exist)."""
    if not wheel.is_file():
        return ""
    with zipfile.ZipFile(wheel) as archive:
        names = [n for n in archive.namelist() if n.endswith(".dist-info/METADATA")]
        text = archive.read(names[0]).decode("utf-8") if names else ""
    match = re.search(r"(?m)^Requires-Python:\s*(.+?)\s*$", text)
    return match.group(1) if match else ""


def _packaging(module: str):
    """``packaging.<module>``, or pip's vendored copy (pip is always there to download)."""
    try:
        return importlib.import_module(f"packaging.{module}")
    except ImportError:
        return importlib.import_module(f"pip._vendor.packaging.{module}")


def _version(wheel) -> str:
    return Path(wheel).name.split("-")[1]


def _project(wheel) -> str:
    return Path(wheel).name.split("-")[0].lower().replace("_", "-")


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
