"""The built zips: manifest contents, the legacy add-on path (bl_info) in a fresh process, and a
manifest with wheels for two Pythons checked by Blender's own validator, builder and installer
filter (fake wheels: no download)."""

import importlib.util
import os
import subprocess
import sys
import textwrap
import tomllib
import zipfile

import pytest

from conftest import EXTENSION_ID, RELEASE_ZIP, ROOT

pytestmark = pytest.mark.blender

_spec = importlib.util.spec_from_file_location("build_addon", ROOT / "build_addon.py")
build_addon = sys.modules.setdefault("build_addon", importlib.util.module_from_spec(_spec))
if not hasattr(build_addon, "main"):
    _spec.loader.exec_module(build_addon)

LINUX = "manylinux_2_28_x86_64"
#: one wheel set per (platform, Python) as build_addon.py bundles them, plus shared ones
TWO_PYTHON_WHEELS = [
    f"scikit_image-0.25.2-cp311-cp311-{LINUX}.whl",
    f"scikit_image-0.25.2-cp313-cp313-{LINUX}.whl",
    "scikit_image-0.25.2-cp311-cp311-win_amd64.whl",
    "scikit_image-0.25.2-cp313-cp313-win_amd64.whl",
    f"scipy-1.17.1-cp311-cp311-manylinux_2_27_x86_64.{LINUX}.whl",
    f"scipy-1.18.1-cp313-cp313-manylinux_2_27_x86_64.{LINUX}.whl",
    "safetensors-0.8.0-cp310-abi3-manylinux_2_17_x86_64.manylinux2014_x86_64.whl",
    "safetensors-0.8.0-cp310-abi3-win_amd64.whl",
    "networkx-3.6.1-py3-none-any.whl",
]


def test_manifest(built_zip):
    with zipfile.ZipFile(built_zip) as archive:
        names = set(archive.namelist())
        manifest = tomllib.loads(archive.read("blender_manifest.toml").decode())
    assert manifest["id"] == EXTENSION_ID and manifest["schema_version"] == "1.0.0"
    assert manifest["blender_version_min"] == "4.2.0"
    platforms = {"linux-x64", "windows-x64", "macos-arm64"}
    # a release zip is one platform's (--split-platforms), with its wheels and no torch
    assert set(manifest["platforms"]) <= platforms if RELEASE_ZIP else platforms
    if RELEASE_ZIP:
        wheels = [n for n in names if n.startswith("wheels/")]
        assert wheels and not any(n.startswith(("wheels/torch-", "wheels/nvidia")) for n in wheels)
    assert "files" in manifest["permissions"] and "network" not in manifest["permissions"]
    assert {"__init__.py", "_core.py", "agndc_core/__init__.py", "agndc_core/pipeline.py"} <= names
    research = ("agndc_core/training", "agndc_core/study", "agndc_core/evaluate",
                "agndc_core/report", "agndc_core/shapes", "agndc_core/nn/agdrnet")
    assert not any(n.startswith(research) or "__pycache__" in n for n in names)
    weights = sorted((ROOT / "agndc_core" / "weights").glob("*.safetensors"))
    assert {f"agndc_core/weights/{w.name}" for w in weights} <= names  # shipped weights vendored


LEGACY_SCRIPT = textwrap.dedent("""
    import os, sys
    import bpy
    bpy.ops.preferences.addon_install(filepath=sys.argv[1])
    bpy.ops.preferences.addon_enable(module="agndc_remesher")
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.mesh.primitive_torus_add()
    result = bpy.ops.object.agndc_remesh(resolution=24, method="mc")
    names = sorted(o.name for o in bpy.data.objects)
    print("RESULT", result, names, flush=True)
    os._exit(0 if result == {"FINISHED"} and "Torus_MC" in names else 1)
""")


@pytest.mark.skipif(bool(RELEASE_ZIP), reason="a release zip has no legacy twin beside it")
def test_legacy_addon_install(built_zip, tmp_path):
    (legacy,) = built_zip.parent.glob(f"{EXTENSION_ID}-*-legacy.zip")
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "user"))
    result = subprocess.run([sys.executable, "-c", LEGACY_SCRIPT, str(legacy)], env=env,
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "Torus_MC" in result.stdout


def _fake_wheels(folder):
    folder.mkdir(parents=True, exist_ok=True)
    for name in TWO_PYTHON_WHEELS:
        project, version = name.split("-")[:2]
        with zipfile.ZipFile(folder / name, "w") as archive:
            archive.writestr(f"{project}-{version}.dist-info/METADATA",
                             f"Metadata-Version: 2.1\nName: {project}\nVersion: {version}\n")


def test_two_python_manifest_validates_and_splits(tmp_path):
    """Blender's validator accepts a manifest listing cp311 and cp313 wheels; --split-platforms
    puts both Pythons' wheels of a platform (and the shared ones) into that platform's zip."""
    stage = build_addon.stage_sources(tmp_path / EXTENSION_ID)
    _fake_wheels(stage / "wheels")
    platforms = ["linux-x64", "windows-x64"]
    build_addon.write_manifest(stage / "blender_manifest.toml", platforms,
                               [f"./wheels/{n}" for n in sorted(TWO_PYTHON_WHEELS)])
    cli = build_addon.ExtensionCLI(None)
    cli.run("validate", str(stage))
    (tmp_path / "dist").mkdir()
    cli.run("build", "--source-dir", str(stage), "--output-dir", str(tmp_path / "dist"),
            "--split-platforms")
    for platform in platforms:
        (zip_path,) = (tmp_path / "dist").glob(f"*-{platform.replace('-', '_')}.zip")
        cli.run("validate", str(zip_path))
        with zipfile.ZipFile(zip_path) as archive:
            inside = {n.rsplit("/", 1)[-1] for n in archive.namelist() if n.endswith(".whl")}
        expected = {n for n in TWO_PYTHON_WHEELS
                    if any(build_addon.fits(n, platform, p) for p in ("3.11", "3.13"))}
        assert inside == expected, platform
        assert any("cp311-cp311" in n for n in inside) and any("cp313-cp313" in n for n in inside)


def test_blender_installs_the_wheels_of_its_own_python():
    """Blender's install-time filter (bl_extension_ops._extensions_wheel_filter_for_this_system)
    on this Linux x86-64 CPython 3.11 keeps exactly what build_addon.fits predicts, and the
    extension is advertised for Python 3.11 and 3.13."""
    import bpy  # noqa: F401  (puts Blender's add-on folders on sys.path)
    from bl_pkg import bl_extension_ops, bl_extension_utils

    assert sys.version_info[:2] == (3, 11)
    kept = bl_extension_ops._extensions_wheel_filter_for_this_system(TWO_PYTHON_WHEELS)
    assert set(kept) == {n for n in TWO_PYTHON_WHEELS if build_addon.fits(n, "linux-x64", "3.11")}
    assert not any("cp313-cp313" in n or "win_amd64" in n for n in kept)
    assert bl_extension_utils.python_versions_from_wheels(TWO_PYTHON_WHEELS) == {(3, 11), (3, 13)}
