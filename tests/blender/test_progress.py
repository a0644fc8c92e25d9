"""The progress a run shows (the worker's callback, drawn by the status bar and the sidebar):
monotone from 0 to 1, no long wait between updates, and messages that name the method running."""

import numpy as np
import pytest
import trimesh

from agndc_core.progress import ProgressLog
from helpers import add_object, cad_part

pytestmark = pytest.mark.blender


def dense_part(triangles: int):
    vertices, faces = cad_part()
    while len(faces) < triangles:
        vertices, faces = trimesh.remesh.subdivide(vertices, faces)
    return vertices, faces


def test_a_sharp_run_with_its_comparison_and_distances(addon):
    """Sharp on a 196,608-triangle part, compared with MC, with the distances of the report:
    the exact intersections and the distances move the bar from inside (they once showed one
    percentage for most of the run), the comparison's messages say MC, and nothing claims a
    network or AGNDC."""
    remesh = addon.remesh
    vertices, faces = dense_part(150_000)
    obj = add_object(addon.mesh_io, "Part", vertices, faces)
    settings = remesh.Settings(resolution=48, method="sharp", threads=1)
    jobs = remesh.mesh_jobs([obj], settings)
    log = ProgressLog()
    remesh.compute_jobs(jobs, settings, progress=log)
    total = log.finish()
    assert jobs[0].error is None
    fractions = np.array([fraction for _, fraction, _ in log.updates])
    assert np.all(np.diff(fractions) >= 0) and fractions[0] == 0.0 and fractions[-1] == 1.0
    messages = [message for _, _, message in log.updates]
    assert not any(word in m for m in messages for word in ("AGNDC", "network", "predict"))
    comparison = [m for m in messages if "marching cubes" in m]
    assert comparison and all(m.startswith("Part: MC ") for m in comparison)
    # each remesh says which one ended; the run's "done" is the last update
    assert [m for m in messages if m.endswith("done")] == ["Part: Sharp done", "Part: MC done",
                                                          "Part: done", "done"]
    assert {"Part: sampling noise of the distance", "Part: distance of Sharp to the source",
            "Part: distance of MC to the source"} <= set(messages)
    gap, before, after = log.longest_gap()
    flat, percent, first = log.longest_flat()
    assert gap < 0.5 * total, (gap, total, before, after)
    assert flat < 0.5 * total, (flat, total, percent, first)
