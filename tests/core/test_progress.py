"""pipeline progress: one monotone 0 -> 1 sequence across voxelising, labels and remeshing;
the time it reports."""

import time

import pytest

from agndc_core.errors import CancelledError
from agndc_core.pipeline import remesh_mesh, subrange
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
