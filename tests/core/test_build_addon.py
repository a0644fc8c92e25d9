"""build_addon.py without bpy or a network: wheel sources, tags per Python, the CUDA refusal,
merging two Pythons' wheel sets and the error for an unresolvable set (fake wheels only)."""

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
#: PyPI's torch 2.13.0 Requires-Dist (the same lines in its Linux, Windows and macOS wheels)
PYPI_TORCH_REQUIRES = [
    "filelock", "typing-extensions>=4.10.0", "sympy>=1.13.3", "networkx>=2.5.1",
    'cuda-toolkit[cublas,cudart]==13.0.3; platform_system == "Linux"',
    'nvidia-cudnn-cu13==9.20.0.48; platform_system == "Linux"',
    'triton==3.7.1; platform_system == "Linux" and python_version < "3.15"',
    'pyyaml; extra == "pyyaml"',
]


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


# -- CUDA refusal ---------------------------------------------------------------------------

@pytest.mark.parametrize("names, culprit", [
    ([f"torch-2.13.0+cu126-cp311-cp311-{LINUX}.whl"], "+cu126"),
    ([f"torch-2.13.0+rocm6.4-cp311-cp311-{LINUX}.whl"], "+rocm6.4"),
    ([f"torch-2.13.0+cpu-cp311-cp311-{LINUX}.whl",
      f"nvidia_cublas_cu12-12.8.4.1-py3-none-{LINUX}.whl"], "nvidia_cublas_cu12"),
    ([f"torch-2.13.0+cpu-cp311-cp311-{LINUX}.whl",
      f"triton-3.7.1-cp311-cp311-{LINUX}.whl"], "triton-3.7.1"),
    ([f"cuda_toolkit-13.0.3-py3-none-{LINUX}.whl"], "cuda_toolkit"),
])
def test_refuses_cuda_wheel_sets(names, culprit):
    with pytest.raises(SystemExit, match="refusing to bundle a CUDA build") as caught:
        build_addon.check_cpu_only(names, "linux-x64", "3.11")
    message = str(caught.value)
    assert culprit in message and "linux-x64, Python 3.11" in message
    assert "--torch-index" in message and "--find-links" in message


def test_accepts_cpu_wheel_set():
    build_addon.check_cpu_only(
        [f"torch-2.13.0+cpu-cp313-cp313-{LINUX}.whl", "torch-2.13.0-cp313-cp313-win_amd64.whl",
         "scipy-1.17.1-cp313-cp313-win_amd64.whl", "sympy-1.14.0-py3-none-any.whl"],
        "linux-x64", "3.13")


def test_refuses_torch_built_for_cuda_without_local_version(tmp_path):
    """PyPI's Linux wheel is named torch-2.13.0-cp311-… (no +cu130): torch/version.py tells."""
    cuda = fake_wheel(tmp_path, f"torch-2.13.0-cp311-cp311-{LINUX}.whl",
                      files={"torch/version.py": "__version__ = '2.13.0+cu130'\n"
                                                 "cuda: Optional[str] = '13.0'\n"})
    with pytest.raises(SystemExit, match=r"CUDA 13\.0 build"):
        build_addon.check_cpu_only([cuda], "linux-x64", "3.11")
    (tmp_path / "cpu").mkdir()
    cpu = fake_wheel(tmp_path / "cpu", "torch-2.13.0-cp311-cp311-win_amd64.whl",
                     files={"torch/version.py": "cuda: Optional[str] = None\n"})
    build_addon.check_cpu_only([cpu], "windows-x64", "3.11")


@pytest.mark.parametrize("platform, python, cuda", [
    ("linux-x64", "3.11", True), ("linux-x64", "3.13", True),
    ("windows-x64", "3.11", False), ("macos-arm64", "3.13", False)])
def test_torch_requirements_per_target(tmp_path, platform, python, cuda):
    """PyPI torch's CUDA requirements apply on Linux only and are refused there."""
    wheel = fake_wheel(tmp_path, "torch-2.13.0-cp311-cp311-any.whl", requires=PYPI_TORCH_REQUIRES)
    requirements = build_addon._requirements_for(wheel, platform, python)
    assert "sympy>=1.13.3" in requirements and not any("pyyaml" in r for r in requirements)
    assert any(r.startswith("nvidia-cudnn") for r in requirements) == cuda
    if cuda:
        with pytest.raises(SystemExit, match="torch requires triton==3.7.1"):
            build_addon.check_cpu_only([], platform, python, requirements=requirements)
    else:
        build_addon.check_cpu_only([], platform, python, requirements=requirements)


# -- tags and sources per Python ------------------------------------------------------------

@pytest.mark.parametrize("python, own, other", [("3.11", "cp311", "cp313"),
                                                ("3.13", "cp313", "cp311")])
def test_pip_command_per_python(tmp_path, python, own, other):
    command = build_addon.pip_download_command(
        "linux-x64", python, tmp_path, ["scipy>=1.11"], [], deps=True,
        constraints=tmp_path / "c.txt")
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


def test_torch_source_per_platform():
    online = build_addon.WheelSources(torch_index="https://example.org/cpu",
                                      find_links=["/wheels"])
    assert online.pip_args("linux-x64", "torch") == [
        "--index-url", "https://example.org/cpu", "--find-links", "/wheels"]
    offline = build_addon.WheelSources(torch_index=None, find_links=["/wheels"])
    assert offline.pip_args("linux-x64", "torch") == ["--no-index", "--find-links", "/wheels"]
    for sources in (online, offline):  # PyPI's Windows/macOS torch is a CPU build
        assert sources.pip_args("windows-x64", "torch") == ["--find-links", "/wheels"]
        assert sources.pip_args("linux-x64", "deps") == ["--find-links", "/wheels"]


def test_parse_args_torch_index_default(tmp_path):
    args = build_addon.parse_args([])
    assert args.torch_index == build_addon.TORCH_CPU_INDEX and args.python == ["3.11", "3.13"]
    args = build_addon.parse_args(["--find-links", str(tmp_path), "--python", "3.11"])
    assert args.torch_index is None and args.python == ["3.11"]
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
    """No cp313 CPU torch in the folder: one error naming the platform, Python and Blender."""
    stderr = "ERROR: Could not find a version that satisfies the requirement torch==2.13.0\n"

    def fake_run(command, **kwargs):
        return subprocess.CompletedProcess(command, 1, stderr=stderr)

    monkeypatch.setattr(build_addon.subprocess, "run", fake_run)
    sources = build_addon.WheelSources(torch_index=None, find_links=[tmp_path])
    with pytest.raises(SystemExit) as caught:
        build_addon.download_wheels("linux-x64", "3.13", sources, tmp_path / "cache")
    message = str(caught.value)
    for part in ("linux-x64, Python 3.13 (Blender 5.1+)", "torch==2.13.0", "+cpu wheel",
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


def test_missing_torch_is_not_retried_without_pins(tmp_path, monkeypatch):
    calls = []

    def fake_download(platform, python, sources, cache, *, pins=()):
        calls.append(list(pins))
        raise build_addon.UnresolvedError("no cp313 torch", ["torch==2.13.0"])

    monkeypatch.setattr(build_addon, "download_wheels", fake_download)
    earlier = {"3.11": [tmp_path / "networkx-3.6.1-py3-none-any.whl"]}
    with pytest.raises(SystemExit, match="no cp313 torch"):
        build_addon.download_consistent("linux-x64", "3.13", build_addon.WheelSources(),
                                        tmp_path, earlier)
    assert calls == [["networkx==3.6.1"]]
