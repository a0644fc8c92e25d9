"""The built zips: manifest contents, and the legacy add-on path (bl_info) in a fresh process."""

import os
import subprocess
import sys
import textwrap
import tomllib
import zipfile

import pytest
from conftest import EXTENSION_ID, ROOT

pytestmark = pytest.mark.blender


def test_manifest(built_zip):
    with zipfile.ZipFile(built_zip) as archive:
        names = set(archive.namelist())
        manifest = tomllib.loads(archive.read("blender_manifest.toml").decode())
    assert manifest["id"] == EXTENSION_ID and manifest["schema_version"] == "1.0.0"
    assert manifest["blender_version_min"] == "4.2.0"
    assert set(manifest["platforms"]) == {"linux-x64", "windows-x64", "macos-arm64"}
    assert "files" in manifest["permissions"] and "network" not in manifest["permissions"]
    assert {"__init__.py", "_core.py", "agndc_core/__init__.py", "agndc_core/pipeline.py"} <= names
    assert not any(n.startswith("agndc_core/training") or "__pycache__" in n for n in names)
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


def test_legacy_addon_install(built_zip, tmp_path):
    (legacy,) = built_zip.parent.glob(f"{EXTENSION_ID}-*-legacy.zip")
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "user"))
    result = subprocess.run([sys.executable, "-c", LEGACY_SCRIPT, str(legacy)], env=env,
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "Torus_MC" in result.stdout
