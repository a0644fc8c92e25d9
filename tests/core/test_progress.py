"""pipeline progress: one monotone 0 -> 1 sequence across voxelising, labels and remeshing,
spread over the stages by their expected time and moving inside the long ones; the time it
reports."""

import time

import numpy as np
import pytest
import trimesh

from agndc_core.errors import CancelledError
from agndc_core.options import RemeshOptions
from agndc_core.pipeline import MESH_ONLY_METHODS, expected_stages, remesh_mesh, subrange
from agndc_core.plan import NETWORK_SECONDS, STAGE_SECONDS
from agndc_core.progress import LINEAR_SHARE, ProgressLog, Stages, interpolated_share
from agndc_core.study.shapes import cad_part


@pytest.mark.parametrize("method", ["mc", "sharp", "surfacenets"])
def test_remesh_mesh_progress_is_monotone(method):
    vertices, faces = cad_part(7)
    calls = []
    remesh_mesh(vertices, faces, resolution=24, method=method,
                progress=lambda f, m: calls.append((f, m)))
    fractions = [f for f, _ in calls]
    assert fractions == sorted(fractions) and fractions[0] == 0.0 and fractions[-1] == 1.0
    assert calls[0][1] == "voxelise"
    assert ("exact intersections" in {m for _, m in calls}) == (method == "sharp")


def test_cancel_between_stages():
    class CancelAfterVoxelise:
        calls = 0

        def is_set(self):
            self.calls += 1
            return self.calls > 1

    vertices, faces = cad_part(7)
    with pytest.raises(CancelledError):
        remesh_mesh(vertices, faces, resolution=24, method="sharp", cancel=CancelAfterVoxelise())


def test_subrange():
    seen = []
    sub = subrange(lambda f, m: seen.append(f), 0.2, 0.6)
    sub(0.0, "a")
    sub(1.0, "b")
    assert seen == [0.2, 0.6] and subrange(None, 0, 1) is None


@pytest.mark.parametrize("method", ["mc", "sharp", "surfacenets"])
def test_remesh_mesh_reports_its_wall_time_once(method):
    """The seconds a user sees (CLI, batch, Blender, eval rows) lie between the sum of the
    timed stages and the wall time around the call: each stage counted once."""
    vertices, faces = cad_part(7)
    start = time.perf_counter()
    result = remesh_mesh(vertices, faces, resolution=24, method=method)
    wall = time.perf_counter() - start
    assert sum(result.timings.values()) <= result.seconds <= wall
    assert {"voxelise", "dual contouring" if method != "mc" else "marching cubes"} <= \
        set(result.timings)


def test_interpolated_share_is_linear_then_creeps_towards_the_end():
    ratios = np.linspace(0.0, 20.0, 2001)
    shares = np.array([interpolated_share(r, 1.0) for r in ratios])
    assert np.all(np.diff(shares) > 0) and shares.max() < 1.0  # never still, never past the end
    assert interpolated_share(1.0, 2.0) == pytest.approx(0.5)
    assert interpolated_share(LINEAR_SHARE * 3, 3.0) == pytest.approx(LINEAR_SHARE)
    assert interpolated_share(2.0, 1.0) > 0.9  # twice as long as expected: still moving
    assert interpolated_share(1.0, 0.0) == 0.0


def test_stages_spread_the_bar_by_expected_time_and_move_inside_a_stage():
    log = ProgressLog()
    stages = Stages(log, None, {"slow": 3.0, "quick": 1.0}, prefix="Part: ")
    assert stages.span("slow") == (0.0, 0.75) and stages.span("quick") == (0.75, 1.0)

    def work():  # a long stage that checks for cancellation between its chunks
        for _ in range(8):
            time.sleep(0.05)
            stages.check()

    stages.run("slow", work)
    stages.run("quick", lambda: None)
    inside = [fraction for _, fraction, message in log.updates if message == "Part: slow"]
    assert inside[0] == 0.0 and len(inside) >= 3 and inside == sorted(inside)
    assert 0.0 < inside[-1] < 0.75
    assert [f for _, f, m in log.updates if m == "Part: quick"] == [0.75]
    assert set(stages.timings) == {"slow", "quick"}


@pytest.mark.parametrize("method, changes", [
    ("agndc", {}), ("agndc", {"flat_patches": False, "normal_filter": False}),
    ("agndc", {"source_bounds": False, "target_faces": 200}), ("agndc_fast", {}),
    ("undc", {}), ("surfacenets", {}), ("sharp", {}), ("oracle_binary", {}), ("mc", {}),
    ("mc_taubin", {})])
def test_the_planned_stages_are_the_stages_that_run(method, changes):
    """The spans of the bar are planned before a run (``expected_stages``): they name the
    stages ``remesh`` then runs, in its order."""
    vertices, faces = cad_part(7)
    options = RemeshOptions(method=method, resolution=20, **changes)
    result = remesh_mesh(vertices, faces, options, progress=lambda f, m: None)
    planned = expected_stages(options, crossings=1e4, points=1e5, bounded=True)
    before = ["voxelise"] + (["exact intersections"] if method in MESH_ONLY_METHODS else [])
    assert list(result.timings) == before + list(planned)
    # every stage has its expected time (the network's per learned method)
    assert all(name in STAGE_SECONDS or (name == "predict" and method in NETWORK_SECONDS)
               for name in [*before, *planned])


def dense_part(triangles: int):
    vertices, faces = cad_part(7)
    while len(faces) < triangles:
        vertices, faces = trimesh.remesh.subdivide(vertices, faces)
    return vertices, faces


@pytest.mark.parametrize("method, resolution", [("sharp", 48), ("agndc", 64)])
def test_progress_keeps_moving_through_a_long_run(method, resolution):
    """On a 196,608-triangle part the bar never waits long: no gap between two updates and no
    whole percentage shown for more than a bounded share of the run (Sharp's exact
    intersections, most of its run, once reported nothing until they ended: one gap of about
    90 %), the fraction only grows and reaches 1, and a Sharp run never claims a network."""
    vertices, faces = dense_part(150_000)
    log = ProgressLog()
    remesh_mesh(vertices, faces, resolution=resolution, method=method, progress=log)
    total = log.finish()
    fractions = [fraction for _, fraction, _ in log.updates]
    assert fractions == sorted(fractions) and fractions[-1] == 1.0
    gap, before, after = log.longest_gap()
    flat, percent, first = log.longest_flat()
    assert gap < 0.5 * total, (gap, total, before, after)
    assert flat < 0.5 * total, (flat, total, percent, first)
    if method == "sharp":
        assert not any("network" in m or "predict" in m for _, _, m in log.updates)
