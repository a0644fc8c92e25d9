"""pytest inside Blender: the bpy module (bpy==4.5.* from PyPI, in .venv-bpy).

The session builds the extension (``build_addon.py --no-wheels``: the core's dependencies come
from the venv, which has no torch, as a user's Blender has none), installs the zip into a
temporary Blender user folder with Blender's own installer and enables it. Every test starts
from an empty scene.

bpy 4.5 can hang at interpreter exit (a registered timer plus exporters), so
``pytest_unconfigure`` ends the process with ``os._exit`` and pytest's exit status.
"""

import importlib
import os
import subprocess
import sys
import tempfile
from pathlib import Path

# Blender reads these once, on import: keep the user's own config, extensions and temp clean.
_TEMP = Path(tempfile.mkdtemp(prefix="agndc_bpy_"))
os.environ.setdefault("BLENDER_USER_RESOURCES", str(_TEMP / "user"))
os.environ.setdefault("TMPDIR", str(_TEMP / "tmp"))
os.makedirs(os.environ["TMPDIR"], exist_ok=True)
tempfile.tempdir = None  # re-read TMPDIR

import pytest  # noqa: E402

bpy = pytest.importorskip("bpy")

ROOT = Path(__file__).resolve().parents[2]
EXTENSION_ID = "agndc_remesher"
MODULE = f"bl_ext.user_default.{EXTENSION_ID}"
WEIGHTS = ROOT / "agndc_core" / "weights" / "agndc.safetensors"

_exit_status = 0


#: a built extension zip to test instead of the developer build: with its wheels, in a venv
#: holding only bpy, numpy and pytest (``docs/blender.md``, "Testing a release zip")
RELEASE_ZIP = os.environ.get("AGNDC_EXTENSION_ZIP")


def _install(zip_path) -> None:
    result = bpy.ops.extensions.package_install_files(
        filepath=str(zip_path), repo="user_default", enable_on_install=True)
    assert result == {"FINISHED"}
    assert MODULE in bpy.context.preferences.addons.keys()


def pytest_configure(config):
    """A release zip is installed before the tests are collected: its bundled wheels (scipy,
    trimesh, ...) are what the tests' own imports of the core then find."""
    if RELEASE_ZIP:
        _install(RELEASE_ZIP)
        sys.path.insert(0, str(ROOT))  # the core's source, for the tests' reference calls


@pytest.fixture(scope="session")
def built_zip(tmp_path_factory) -> Path:
    """The extension under test: ``AGNDC_EXTENSION_ZIP``, else the developer build (no
    wheels) made by build_addon.py."""
    if RELEASE_ZIP:
        return Path(RELEASE_ZIP)
    out = tmp_path_factory.mktemp("dist")
    subprocess.run([sys.executable, str(ROOT / "build_addon.py"), "--no-wheels", "--legacy",
                    "--out", str(out), "--build-dir", str(tmp_path_factory.mktemp("build"))],
                   check=True, capture_output=True, text=True)
    (zip_path,) = [p for p in out.glob(f"{EXTENSION_ID}-*.zip") if "legacy" not in p.name]
    return zip_path


@pytest.fixture(scope="session")
def addon(built_zip):
    """The installed and enabled extension: a namespace of its submodules."""
    if not RELEASE_ZIP:
        _install(built_zip)

    class Addon:
        module = MODULE
        package = importlib.import_module(MODULE)
        remesh = importlib.import_module(f"{MODULE}.remesh")
        mesh_io = importlib.import_module(f"{MODULE}.mesh_io")
        core = importlib.import_module(f"{MODULE}._core")

    return Addon


@pytest.fixture(autouse=True)
def empty_scene():
    bpy.ops.wm.read_homefile(use_empty=True)
    yield


def pytest_sessionfinish(session, exitstatus):
    global _exit_status
    _exit_status = int(exitstatus)


def pytest_unconfigure(config):
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(_exit_status)
