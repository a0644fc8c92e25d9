"""Batch remeshing: ``agndc batch`` and ``batch.remesh_many`` on mixed folders,
manifests, a local process pool and a Dask LocalCluster; resumability, failure isolation, and
what a Ctrl-C or kill leaves behind. Outputs are compared byte for byte with ``agndc remesh``."""

import csv
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from agndc_core import batch
from agndc_core.cli import main
from agndc_core.errors import AGNDCError
from agndc_core.gridio import TEMP_MARK, load_grid, save_grid, save_mesh
from agndc_core.pipeline import remesh_file, resolution_for_voxel_size
from agndc_core.study.shapes import generate_shape
from agndc_core.voxelize import voxelize
from conftest import REPO

RES = 20  # mesh inputs; grids are used as they are
N_SPHERES = 100  # kill tests: the run takes about a second after the first output
GOOD = {"a.npy": "a.ply", "sub/b.binvox": "sub/b.ply", "c.obj": "c.ply"}
BAD = {"broken.binvox": "truncated", "empty.npy": "empty"}


@pytest.fixture(scope="module")
def mixed(tmp_path_factory):
    """Two grid files, one mesh, one corrupt file and one empty grid (and a non-input file)."""
    folder = tmp_path_factory.mktemp("mixed")
    (folder / "sub").mkdir()
    shapes = [generate_shape(seed) for seed in (1, 2, 3)]
    save_grid(voxelize(*shapes[0], 18), folder / "a.npy")
    save_grid(voxelize(*shapes[1], 16), folder / "sub" / "b.binvox")
    save_mesh(*shapes[2], folder / "c.obj")
    (folder / "broken.binvox").write_bytes(b"#binvox 1\ndim 8 8 8\ntranslate 0 0 0\nscale 1\n"
                                           b"data\n\x01")
    np.save(folder / "empty.npy", np.zeros((8, 8, 8), dtype=bool))
    (folder / "notes.txt").write_text("not an input: only manifests given by name are read\n")
    return folder


@pytest.fixture(scope="module")
def reference(mixed, tmp_path_factory):
    """Single-file ``agndc remesh --method mc`` output bytes per good input."""
    out = tmp_path_factory.mktemp("single")
    expected = {}
    for name in GOOD:
        target = out / f"{Path(name).stem}.ply"
        assert main(["remesh", str(mixed / name), "-o", str(target), "--method", "mc",
                     "--res", str(RES)]) == 0
        expected[name] = target.read_bytes()
    return expected


def rows_by_input(folder, root) -> dict:
    with open(folder / "batch.csv", newline="", encoding="utf-8") as handle:
        return {Path(r["input"]).relative_to(root).as_posix(): r for r in csv.DictReader(handle)}


def batch_args(inputs, out, *extra):
    return ["batch", *map(str, inputs), "-o", str(out), "--method", "mc", "--res", str(RES),
            "--no-progress", *extra]


def test_cli_mixed_folder_then_resume(mixed, reference, tmp_path, capsys):
    out = tmp_path / "out"
    assert main(batch_args([mixed], out, "--workers", "2")) == 1
    rows = rows_by_input(out, mixed)
    assert set(rows) == set(GOOD) | set(BAD)
    for name, output in GOOD.items():
        row = rows[name]
        assert row["status"] == "ok" and row["error"] == "", row
        assert Path(row["output"]) == out / output
        assert (out / output).read_bytes() == reference[name]  # = single-file agndc remesh
        assert int(row["faces"]) > 100 and "x" in row["grid"] and float(row["seconds"]) >= 0
        assert float(row["peak_rss_mb"]) > 10
    assert rows["c.obj"]["grid"].split("x")[0] == str(RES)  # mesh voxelised at --res
    for name, problem in BAD.items():
        assert rows[name]["status"] == "failed"
        assert name in rows[name]["error"] and problem in rows[name]["error"]
        assert not (out / f"{Path(name).stem}.ply").exists()
    err = capsys.readouterr().err
    assert "FAILED" in err and "broken.binvox" in err and "empty.npy" in err

    # second run: every good output is up to date, so skipped; the bad inputs fail again
    mtimes = {name: (out / output).stat().st_mtime_ns for name, output in GOOD.items()}
    assert main(batch_args([mixed], out, "--workers", "2")) == 1
    again = rows_by_input(out, mixed)
    assert {name: again[name]["status"] for name in GOOD} == dict.fromkeys(GOOD, "skipped")
    assert {name: again[name]["status"] for name in BAD} == dict.fromkeys(BAD, "failed")
    assert again["a.npy"]["faces"] == rows["a.npy"]["faces"]  # the previous numbers are kept
    assert {name: (out / o).stat().st_mtime_ns for name, o in GOOD.items()} == mtimes

    # --overwrite redoes them (serially this time: same bytes)
    assert main(batch_args([mixed], out, "--workers", "1", "--overwrite")) == 1
    redone = rows_by_input(out, mixed)
    assert {name: redone[name]["status"] for name in GOOD} == dict.fromkeys(GOOD, "ok")
    assert all((out / o).read_bytes() == reference[n] for n, o in GOOD.items())
    assert not any(TEMP_MARK in p.name for p in out.rglob("*"))


def test_all_good_exit_zero_and_output_inside_input_folder(mixed, tmp_path):
    folder = tmp_path / "in"
    folder.mkdir()
    (folder / "a.npy").write_bytes((mixed / "a.npy").read_bytes())
    out = folder / "meshes"  # inside the input folder: never read back as input
    assert main(batch_args([folder], out, "--workers", "1", "--format", "obj")) == 0
    assert main(batch_args([folder], out, "--workers", "1", "--format", "obj")) == 0
    assert sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*")) == [
        "a.npy", "meshes", "meshes/a.obj", "meshes/batch.csv"]
    assert batch.read_rows(out / "batch.csv")[0]["status"] == "skipped"


def test_input_newer_than_output_is_redone(mixed, tmp_path):
    src = tmp_path / "g.npy"
    src.write_bytes((mixed / "a.npy").read_bytes())
    out = tmp_path / "out"
    assert batch.remesh_many([src], out, method="mc", workers=1)[0]["status"] == "ok"
    past = src.stat().st_mtime_ns - 10**9
    os.utime(out / "g.ply", ns=(past, past))  # the input was edited after this output was made
    assert batch.remesh_many([src], out, method="mc", workers=1)[0]["status"] == "ok"
    assert batch.remesh_many([src], out, method="mc", workers=1)[0]["status"] == "skipped"


def test_voxel_size_matches_single_file_remesh(mixed, tmp_path):
    out = tmp_path / "out"
    rows = batch.remesh_many([mixed / "c.obj"], out, method="surfacenets", voxel_size=0.05,
                             workers=1)
    single = tmp_path / "single.ply"
    assert main(["remesh", str(mixed / "c.obj"), "-o", str(single), "--method", "surfacenets",
                 "--voxel-size", "0.05"]) == 0
    assert (out / "c.ply").read_bytes() == single.read_bytes()
    assert rows[0]["grid"].split("x")[0] == "22"  # longest side 1.0 / 0.05 = 20 voxels + 2
    vertices = np.array([[0, 0, 0], [1.0, 0.5, 0.25]])
    assert resolution_for_voxel_size(vertices, 0.1) == 12
    assert resolution_for_voxel_size(vertices, 0.3) == 6  # ceil(3.33) + 2: voxels <= 0.3
    with pytest.raises(AGNDCError, match="voxel size"):
        resolution_for_voxel_size(vertices, 0.0)


def test_agndc_pool_equals_serial_and_single_file(mixed, tmp_path):
    """The learned method through the local pool (model loaded once per worker) and serially."""
    inputs = [mixed / "a.npy", mixed / "sub" / "b.binvox"]
    pool = batch.remesh_many(inputs, tmp_path / "pool", method="agndc", workers=2)
    serial = batch.remesh_many(inputs, tmp_path / "serial", method="agndc", workers=1)
    assert [r["status"] for r in pool] == [r["status"] for r in serial] == ["ok", "ok"]
    # the pool's processes did the work, not this one; which of them took which file is the
    # executor's choice (a worker that is ready first may take both: seen in CI)
    here = f"{socket.gethostname()}:{os.getpid()}"
    assert {r["worker"] for r in serial} == {here}
    assert here not in {r["worker"] for r in pool}
    single = tmp_path / "single.ply"
    assert main(["remesh", str(inputs[0]), "-o", str(single), "--method", "agndc"]) == 0
    assert (tmp_path / "pool" / "a.ply").read_bytes() == single.read_bytes()
    for name in ("a.ply", "b.ply"):
        assert (tmp_path / "pool" / name).read_bytes() == (tmp_path / "serial" / name).read_bytes()


@pytest.mark.slow
def test_dask_local_cluster_scheduler(mixed, reference, tmp_path):
    distributed = pytest.importorskip("distributed")
    out = tmp_path / "out"
    with distributed.LocalCluster(n_workers=2, processes=True, threads_per_worker=1,
                                  dashboard_address=None) as cluster:
        status = main(batch_args([mixed], out, "--engine", "dask",
                                 "--scheduler", cluster.scheduler_address))
    assert status == 1
    rows = rows_by_input(out, mixed)
    assert {n: r["status"] for n, r in rows.items()} == {**dict.fromkeys(GOOD, "ok"),
                                                         **dict.fromkeys(BAD, "failed")}
    assert all((out / o).read_bytes() == reference[n] for n, o in GOOD.items())
    assert "truncated" in rows["broken.binvox"]["error"]
    # the cluster's workers did the work (which of them took what is the scheduler's choice)
    assert f"{socket.gethostname()}:{os.getpid()}" not in {r["worker"] for r in rows.values()}


@pytest.mark.slow
def test_dask_own_cluster_agndc(mixed, tmp_path):
    """No scheduler: a LocalCluster of 2 processes; the network is loaded by the worker plugin."""
    pytest.importorskip("distributed")
    inputs = [mixed / "a.npy", mixed / "c.obj"]
    rows = batch.remesh_many(inputs, tmp_path / "dask", method="agndc", resolution=RES,
                             workers=2, engine="dask")
    assert [r["status"] for r in rows] == ["ok", "ok"]
    serial = batch.remesh_many(inputs, tmp_path / "serial", method="agndc", resolution=RES,
                               workers=1)
    assert [r["faces"] for r in rows] == [r["faces"] for r in serial]
    for name in ("a.ply", "c.ply"):
        assert (tmp_path / "dask" / name).read_bytes() == (tmp_path / "serial" / name).read_bytes()


def test_manifests(mixed, reference, tmp_path):
    listing = tmp_path / "list.txt"
    sub = os.path.relpath(mixed / "sub", tmp_path)  # relative to the manifest's folder
    listing.write_text(f"# a comment\n{mixed / 'a.npy'}\n\n{sub}\nmissing.npy\n")
    table = tmp_path / "table.csv"
    table.write_text(f"input,output\n{mixed / 'c.obj'},meshes/part.ply\n")
    out = tmp_path / "out"
    rows = batch.remesh_many([listing, table], out, method="mc", resolution=RES, workers=1)
    by_name = {Path(r["input"]).name: r for r in rows}
    assert {n: r["status"] for n, r in by_name.items()} == {
        "a.npy": "ok", "b.binvox": "ok", "missing.npy": "failed", "c.obj": "ok"}
    assert "missing.npy" in by_name["missing.npy"]["error"]
    assert "not found" in by_name["missing.npy"]["error"]
    assert (out / "meshes" / "part.ply").read_bytes() == reference["c.obj"]
    assert (out / "b.ply").read_bytes() == reference["sub/b.binvox"]


@pytest.mark.parametrize("args, message", [
    (["nope"], "no such file"),
    (["{clash}"], "would both be written"),
    (["{empty}"], "no mesh or grid files"),
    (["{mixed}", "--engine", "local", "--scheduler", "tcp://127.0.0.1:1"], "dask engine"),
    (["{mixed}/a.npy", "--method", "agndc", "--checkpoint", "nope.safetensors"], "not found"),
])
def test_usage_errors_exit_2(mixed, tmp_path, capsys, args, message):
    clash = tmp_path / "clash"
    clash.mkdir()
    np.save(clash / "x.npy", np.ones((3, 3, 3), dtype=bool))
    save_grid(load_grid(clash / "x.npy"), clash / "x.binvox")
    (tmp_path / "empty").mkdir()
    paths = {"clash": clash, "empty": tmp_path / "empty", "mixed": mixed}
    args = [a.format(**paths) for a in args]
    assert main(["batch", *args, "-o", str(tmp_path / "out"), "--no-progress"]) == 2
    assert message in capsys.readouterr().err


def test_output_folder_is_input_folder_and_exclusive_sizes(mixed, tmp_path, capsys):
    assert main(["batch", str(mixed), "-o", str(mixed)]) == 2
    (tmp_path / "c.obj").write_bytes((mixed / "c.obj").read_bytes())
    assert main(["batch", str(tmp_path / "c.obj"), "-o", str(tmp_path), "--format", "obj"]) == 2
    assert "would replace it" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        main(["batch", str(mixed), "-o", str(tmp_path), "--res", "8", "--voxel-size", "0.1"])
    assert exc.value.code == 2


def test_dask_missing_is_a_clear_error(monkeypatch, mixed, tmp_path):
    monkeypatch.setitem(sys.modules, "distributed", None)  # import distributed -> ImportError
    monkeypatch.delitem(sys.modules, "agndc_core.batch_dask", raising=False)
    with pytest.raises(AGNDCError, match=r"pip install 'agndc-remesher\[dask\]'"):
        batch.remesh_many([mixed / "a.npy"], tmp_path / "o", method="mc", engine="dask")


def test_core_imports_without_dask():
    code = ("import sys; sys.modules['dask'] = sys.modules['distributed'] = None; "
            "import agndc_core.batch, agndc_core.cli; agndc_core.cli._parser(); print('ok')")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            timeout=120)
    assert result.stdout.strip() == "ok", result.stderr


def test_interrupted_write_leaves_old_file_and_no_temp(tmp_path, monkeypatch):
    import agndc_core.gridio as gridio

    target = tmp_path / "m.ply"
    vertices = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=float)
    faces = np.array([[0, 1, 2]])
    save_mesh(vertices, faces, target)
    before = target.read_bytes()

    def interrupted(src, dst):
        raise KeyboardInterrupt  # Ctrl-C between writing the temporary file and the rename

    monkeypatch.setattr(gridio.os, "replace", interrupted)
    with pytest.raises(KeyboardInterrupt):
        save_mesh(vertices * 2, faces, target)
    assert target.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.ply"]
    assert gridio.temp_path(tmp_path / "x.nii.gz").name == f"x{TEMP_MARK}{os.getpid()}.nii.gz"


def test_leftover_temp_files_are_swept(mixed, tmp_path):
    out = tmp_path / "out"
    (out / "sub").mkdir(parents=True)
    (out / "sub" / f"b{TEMP_MARK}12345.ply").write_bytes(b"partial")
    (out / "keep.tmp-notes.txt").write_text("not ours")
    batch.remesh_many([mixed / "a.npy"], out, method="mc", workers=1)
    names = sorted(p.relative_to(out).as_posix() for p in out.rglob("*"))
    assert names == ["a.ply", "batch.csv", "keep.tmp-notes.txt", "sub"]


def crash_on_marked(job, options):
    """A job runner for the pool test: the worker process dies on files named crash*."""
    if Path(job.input).name.startswith("crash"):
        os._exit(3)
    return batch.run_job(job, options)


def test_dying_worker_fails_only_its_file(mixed, tmp_path):
    folder = tmp_path / "in"
    folder.mkdir()
    for name in ("crash.npy", "p.npy", "q.npy", "r.npy", "s.npy"):
        (folder / name).write_bytes((mixed / "a.npy").read_bytes())
    jobs = batch.discover_inputs([folder], tmp_path / "out")
    rows = []
    batch.run_pool(jobs, batch.RemeshOptions(method="mc"), 2,
                   lambda job, job_rows: rows.extend(job_rows), func=crash_on_marked)
    status = {Path(r["input"]).name: r["status"] for r in rows}
    assert status == {"crash.npy": "failed", "p.npy": "ok", "q.npy": "ok", "r.npy": "ok",
                      "s.npy": "ok"}
    crashed = next(r for r in rows if r["status"] == "failed")
    assert "worker process died" in crashed["error"]


@pytest.fixture(scope="module")
def spheres(tmp_path_factory):
    """Many small grids, so a run is reliably still going when the first output appears."""
    folder = tmp_path_factory.mktemp("spheres")
    x, y, z = np.mgrid[:32, :32, :32]
    for i in range(N_SPHERES):
        radius = 6 + i % 9
        np.save(folder / f"s{i:03d}.npy", (x - 15.6) ** 2 + (y - 16.2) ** 2 + (z - 15.9) ** 2
                < radius**2)
    return folder


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGKILL])
def test_killed_run_leaves_no_partial_output(spheres, tmp_path, sig):
    out = tmp_path / "out"
    command = [sys.executable, "-m", "agndc_core.cli", "batch", str(spheres), "-o", str(out),
               "--method", "surfacenets", "--workers", "2", "--no-progress"]
    env = dict(os.environ, OMP_NUM_THREADS="1")
    # a suite started in the background (`cmd &`) inherits SIGINT ignored, and Python keeps an
    # ignored SIGINT ignored: the batch would never see the Ctrl-C this test sends
    process = subprocess.Popen(command, cwd=REPO, env=env, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE,
                               preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))

    def finished():  # a file still being written (name.tmp-<pid>.ply) is not finished
        return sorted(p for p in out.glob("*.ply") if TEMP_MARK not in p.name)

    deadline = time.monotonic() + 120
    while not finished() and time.monotonic() < deadline:
        time.sleep(0.01)
    process.send_signal(sig)
    _, err = process.communicate(timeout=60)
    time.sleep(1.5)  # after a SIGKILL the orphaned workers notice within 0.5 s and exit
    done = finished()
    assert 0 < len(done) < N_SPHERES, "the run should have been stopped part way"
    if sig == signal.SIGINT:
        assert process.returncode == 130, err.decode()
        assert not any(TEMP_MARK in p.name for p in out.iterdir())  # cleaned on the way out
        rows = batch.read_rows(out / "batch.csv")
        assert {Path(r["output"]).name for r in rows} <= {p.name for p in done}
    else:
        assert process.returncode == -signal.SIGKILL
    for path in done:  # every output under its final name is complete and right
        expected = tmp_path / "expected.ply"
        result = remesh_file(spheres / f"{path.stem}.npy", method="surfacenets")
        save_mesh(result.vertices, result.faces, expected)
        assert path.read_bytes() == expected.read_bytes(), path.name
    # the next run sweeps what the killed one left, skips what it finished, does the rest
    rows = batch.remesh_many([spheres], out, method="surfacenets", workers=1)
    assert {r["status"] for r in rows if Path(r["output"]) in done} == {"skipped"}
    assert sum(r["status"] == "ok" for r in rows) == N_SPHERES - len(done)
    assert len(list(out.glob("*.ply"))) == N_SPHERES
    assert not any(TEMP_MARK in p.name for p in out.iterdir())


@pytest.mark.parametrize("flag", ["--no-flat-patches", "--no-normal-filter"])
def test_learned_method_switch_reaches_every_job(mixed, tmp_path, flag):
    """``agndc batch --no-flat-patches`` (or ``--no-normal-filter``) gives what ``agndc remesh``
    with the same switch gives, and not what the default (flat patches, the network's mesh
    denoised) gives."""
    source = mixed / "a.npy"
    out = tmp_path / "out"
    assert main(["batch", str(source), "-o", str(out), "--method", "agndc", "--workers", "1",
                 flag, "--no-progress"]) == 0
    switched, default = tmp_path / "switched.ply", tmp_path / "default.ply"
    assert main(["remesh", str(source), "-o", str(switched), flag]) == 0
    assert main(["remesh", str(source), "-o", str(default)]) == 0
    assert (out / "a.ply").read_bytes() == switched.read_bytes()
    assert switched.read_bytes() != default.read_bytes()


def test_no_source_bounds_reaches_every_job(mixed, tmp_path):
    """``agndc batch --no-source-bounds`` gives what ``agndc remesh --no-source-bounds`` gives
    for a mesh, and not what the default (the mesh's bounding box) gives."""
    source = mixed / "c.obj"
    out = tmp_path / "out"
    assert main(["batch", str(source), "-o", str(out), "--method", "surfacenets",
                 "--workers", "1", "--no-source-bounds", "--no-progress"]) == 0
    alone, bounded = tmp_path / "alone.ply", tmp_path / "bounded.ply"
    assert main(["remesh", str(source), "-o", str(alone), "--method", "surfacenets",
                 "--no-source-bounds"]) == 0
    assert main(["remesh", str(source), "-o", str(bounded), "--method", "surfacenets"]) == 0
    assert (out / "c.ply").read_bytes() == alone.read_bytes()
    assert alone.read_bytes() != bounded.read_bytes()
