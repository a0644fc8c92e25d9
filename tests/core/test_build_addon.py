"""build_addon.py without bpy or a network: what is staged (the product without torch or the
research wing), wheel sources, tags per Python, the torch refusal, merging two Pythons' wheel
sets and the error for an unresolvable set (fake wheels only)."""

import importlib.util
import subprocess
import sys
import tomllib
import zipfile

import pytest

from conftest import REPO

spec = importlib.util.spec_from_file_location("build_addon", REPO / "build_addon.py")
build_addon = sys.modules["build_addon"] = importlib.util.module_from_spec(spec)
spec.loader.exec_module(build_addon)

LINUX = "manylinux_2_28_x86_64"


def fake_wheel(folder, name, *, requires=(), requires_python="", files=None):
    """A wheel file with a METADATA (Requires-Dist, Requires-Python) and optional members."""
    project, version = name.split("-")[:2]
    path = folder / name
    lines = ["Metadata-Version: 2.1", f"Name: {project}", f"Version: {version}"]
    lines += [f"Requires-Python: {requires_python}"] if requires_python else []
    lines += [f"Requires-Dist: {r}" for r in requires]
    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr(f"{project}-{version}.dist-info/METADATA", "\n".join(lines) + "\n")
        for member, text in (files or {}).items():
            archive.writestr(member, text)
    return path


# -- what ships -----------------------------------------------------------------------------

@pytest.mark.parametrize("names, culprit", [
    ([f"torch-2.13.0+cpu-cp311-cp311-{LINUX}.whl"], "torch-2.13.0+cpu"),
    ([f"scipy-1.17.1-cp311-cp311-{LINUX}.whl",
      f"nvidia_cublas_cu12-12.8.4.1-py3-none-{LINUX}.whl"], "nvidia_cublas_cu12"),
    ([f"triton-3.7.1-cp311-cp311-{LINUX}.whl"], "triton-3.7.1"),
])
def test_refuses_torch_and_cuda_wheels(names, culprit):
    with pytest.raises(SystemExit, match="refusing to bundle") as caught:
        build_addon.check_no_torch(names, "linux-x64", "3.11")
    assert culprit in str(caught.value) and "linux-x64, Python 3.11" in str(caught.value)
    build_addon.check_no_torch([f"scipy-1.17.1-cp311-cp311-{LINUX}.whl"], "linux-x64", "3.11")


def test_staged_core_is_the_product_without_torch(tmp_path):
    """The extension carries the product path only: no training, evaluation, research or torch
    modules, and nothing staged imports torch."""
    stage = build_addon.stage_sources(tmp_path / "agndc_remesher")
    core = stage / "agndc_core"
    for research in ("training", "study", "evaluate.py", "report.py", "symmetry.py", "solids.py",
                     "shapes.py", "cli.py", "nn/agdrnet.py", "nn/band_ops.py"):
        assert not (core / research).exists(), research
    assert (core / "weights" / "agndc.safetensors").is_file()
    for path in stage.rglob("*.py"):
        text = path.read_text()
        assert "import torch" not in text and "from torch" not in text, path


def test_staged_core_remeshes_without_torch(tmp_path):
    """Every method the add-on offers runs from the staged folder with torch unimportable."""
    stage = build_addon.stage_sources(tmp_path / "agndc_remesher")
    code = f"""
import builtins, sys
real = builtins.__import__
def guarded(name, *args, **kwargs):
    if name.split(".")[0] in ("torch", "safetensors"):
        raise ImportError(name + " is not bundled")
    return real(name, *args, **kwargs)
builtins.__import__ = guarded
# only the staged folder: the editable install's finder would fill in what staging left out
sys.meta_path = [f for f in sys.meta_path if "editable" not in getattr(f, "__module__", "")]
sys.path.insert(0, {str(stage)!r})
import importlib, pkgutil
import numpy as np
import agndc_core
from agndc_core import pipeline
assert pipeline.__file__.startswith({str(stage)!r})
for module in pkgutil.walk_packages(agndc_core.__path__, "agndc_core."):
    importlib.import_module(module.name)  # every staged module's imports are staged too
x, y, z = np.meshgrid(*[np.arange(16)] * 3, indexing="ij")
ball = ((x - 7) ** 2 + (y - 8) ** 2 + (z - 7) ** 2) < 25
for method in ("agndc", "undc", "surfacenets", "mc", "mc_taubin"):
    assert len(pipeline.remesh(ball, method=method).faces) > 100, method
verts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
faces = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
assert len(pipeline.remesh_mesh(verts, faces, resolution=12, method="sharp").faces) > 10
"""
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          cwd=tmp_path)
    assert done.returncode == 0, done.stderr[-2000:]


# -- tags and sources per Python ------------------------------------------------------------

@pytest.mark.parametrize("python, own, other", [("3.11", "cp311", "cp313"),
                                                ("3.13", "cp313", "cp311")])
def test_pip_command_per_python(tmp_path, python, own, other):
    command = build_addon.pip_download_command(
        "linux-x64", python, tmp_path, ["scipy>=1.11"], [], constraints=tmp_path / "c.txt")
    pairs = list(zip(command, command[1:]))
    assert ("--python-version", python) in pairs and ("--implementation", "cp") in pairs
    assert {b for a, b in pairs if a == "--abi"} == {own, "abi3", "none"}
    assert other not in command and "--no-deps" not in command
    assert ("--platform", "manylinux_2_28_x86_64") in pairs and command[-1] == "scipy>=1.11"


@pytest.mark.parametrize("name, fits311, fits313", [
    (f"scipy-1.17.1-cp311-cp311-{LINUX}.whl", True, False),
    (f"scipy-1.17.1-cp313-cp313-{LINUX}.whl", False, True),
    (f"safetensors-0.8.0-cp310-abi3-{LINUX}.whl", True, True),   # stable ABI, older 3.x
    (f"future-1.0-cp314-abi3-{LINUX}.whl", False, False),        # stable ABI, newer 3.x
    ("sympy-1.14.0-py3-none-any.whl", True, True),
    ("six-1.16.0-py2.py3-none-any.whl", True, True),
    (f"scipy-1.17.1-cp311-cp311-{LINUX}.manylinux2014_x86_64.whl", True, False),
])
def test_python_compatibility_as_blender_judges(name, fits311, fits313):
    assert build_addon.python_compatible(name, "3.11") == fits311
    assert build_addon.python_compatible(name, "3.13") == fits313
    assert build_addon.fits(name, "linux-x64", "3.11") == fits311
    pure = name.endswith("-any.whl")
    assert build_addon.fits(name, "windows-x64", "3.11") == (pure and fits311)


def test_find_links_is_offline():
    assert build_addon.WheelSources().pip_args() == []
    assert build_addon.WheelSources(find_links=["/a", "/b"]).pip_args() == [
        "--no-index", "--find-links", "/a", "--find-links", "/b"]


def test_parse_args(tmp_path):
    args = build_addon.parse_args([])
    assert args.find_links == [] and args.python == ["3.11", "3.13"]
    args = build_addon.parse_args(["--find-links", str(tmp_path), "--python", "3.11"])
    assert args.find_links == [tmp_path] and args.python == ["3.11"]
    with pytest.raises(SystemExit):
        build_addon.parse_args(["--find-links", str(tmp_path / "missing")])
    with pytest.raises(SystemExit):
        build_addon.parse_args(["--python", "3.12"])


# -- two Pythons in one zip -----------------------------------------------------------------

def test_merge_keeps_one_version_of_shared_wheels(tmp_path):
    """Blender installs the highest version of a pure wheel for both Pythons: the lower one is
    dropped; platform wheels of each Python stay."""
    a, b = tmp_path / "a", tmp_path / "b"
    a.mkdir(), b.mkdir()
    w311 = [fake_wheel(a, f"scipy-1.17.1-cp311-cp311-{LINUX}.whl"),
            fake_wheel(a, "networkx-3.5-py3-none-any.whl", requires_python=">=3.11")]
    w313 = [fake_wheel(b, f"scipy-1.17.1-cp313-cp313-{LINUX}.whl"),
            fake_wheel(b, "networkx-3.6.1-py3-none-any.whl", requires_python=">=3.11")]
    merged = build_addon.merge_wheel_sets({"3.11": w311, "3.13": w313}, "linux-x64")
    assert [w.name for w in merged] == ["networkx-3.6.1-py3-none-any.whl",
                                        f"scipy-1.17.1-cp311-cp311-{LINUX}.whl",
                                        f"scipy-1.17.1-cp313-cp313-{LINUX}.whl"]


def test_merge_refuses_a_shared_wheel_one_python_cannot_run(tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    a.mkdir(), b.mkdir()
    old = fake_wheel(a, "networkx-3.4-py3-none-any.whl", requires_python=">=3.10")
    new = fake_wheel(b, "networkx-3.9-py3-none-any.whl", requires_python=">=3.12")
    with pytest.raises(SystemExit, match=r"networkx-3\.9.*requires Python >=3\.12"):
        build_addon.merge_wheel_sets({"3.11": [old], "3.13": [new]}, "linux-x64")


def test_manifest_lists_both_pythons(tmp_path):
    wheels = [f"./wheels/scipy-1.17.1-cp311-cp311-{LINUX}.whl",
              f"./wheels/scipy-1.17.1-cp313-cp313-{LINUX}.whl",
              "./wheels/sympy-1.14.0-py3-none-any.whl"]
    path = tmp_path / "blender_manifest.toml"
    build_addon.write_manifest(path, ["linux-x64"], wheels)
    manifest = tomllib.loads(path.read_text())
    assert manifest["wheels"] == wheels and manifest["platforms"] == ["linux-x64"]
    assert "files" in manifest["permissions"]  # tables after the inserted key survive


def test_unresolvable_python_names_python_and_way_out(tmp_path, monkeypatch):
    """No cp313 scipy in the folder: one error naming the platform, Python and Blender."""
    stderr = "ERROR: Could not find a version that satisfies the requirement scipy>=1.11\n"

    def fake_run(command, **kwargs):
        return subprocess.CompletedProcess(command, 1, stderr=stderr)

    monkeypatch.setattr(build_addon.subprocess, "run", fake_run)
    sources = build_addon.WheelSources(find_links=[tmp_path])
    with pytest.raises(SystemExit) as caught:
        build_addon.download_wheels("linux-x64", "3.13", sources, tmp_path / "cache")
    message = str(caught.value)
    for part in ("linux-x64, Python 3.13 (Blender 5.1+)", "scipy>=1.11",
                 "Could not find a version", "--python 3.11", "--find-links DIR"):
        assert part in message, part


def test_later_python_pins_the_wheels_it_shares(tmp_path, monkeypatch):
    """Pure and stable-ABI wheels chosen for 3.11 are pinned for 3.13 (one copy in the zip);
    when the pins do not resolve, the set is resolved again without them."""
    calls = []

    def fake_download(platform, python, sources, cache, *, pins=()):
        calls.append(list(pins))
        if pins:
            raise build_addon.UnresolvedError("no networkx 3.6.1 for 3.13", ["scipy>=1.11"])
        return ["resolved"]

    monkeypatch.setattr(build_addon, "download_wheels", fake_download)
    earlier = {"3.11": [tmp_path / f"scipy-1.17.1-cp311-cp311-{LINUX}.whl",
                        tmp_path / "networkx-3.6.1-py3-none-any.whl",
                        tmp_path / f"safetensors-0.8.0-cp310-abi3-{LINUX}.whl"]}
    sources = build_addon.WheelSources()
    assert build_addon.download_consistent("linux-x64", "3.13", sources, tmp_path,
                                           earlier) == ["resolved"]
    assert calls == [["networkx==3.6.1", "safetensors==0.8.0"], []]
