"""The interactive parts that background mode cannot drive: the modal worker (with a stand-in
window manager and events: progress bar, Esc, one run at a time), the draw functions (with a
recording layout), the time estimate and its confirmation, and drag and drop."""

import importlib
import re
import time
from types import SimpleNamespace

import bpy
import numpy as np
import pytest

from conftest import WEIGHTS
from helpers import add_object, cad_part, scene_state

pytestmark = pytest.mark.blender

TIMER = SimpleNamespace(type="TIMER", value="NOTHING")
ESC = SimpleNamespace(type="ESC", value="PRESS")


class FakeWindowManager:
    def __init__(self):
        self.handlers, self.timers = [], []

    def event_timer_add(self, step, window=None):
        self.timers.append(object())
        return self.timers[-1]

    def event_timer_remove(self, timer):
        self.timers.remove(timer)

    def modal_handler_add(self, op):
        self.handlers.append(op)


class FakeWorkspace:
    def __init__(self):
        self.status = []

    def status_text_set(self, text):
        self.status.append(text)


class RecordingLayout:
    """Enough of UILayout for the draw functions; checks every prop name exists."""

    def __init__(self, log):
        self.log = log
        self.use_property_split = self.use_property_decorate = False
        self.active = True

    def column(self, **_):
        return self

    row = box = column

    def separator(self):
        pass

    def prop(self, data, name, **_):
        assert name in data.bl_rna.properties, name
        self.log.append(("prop", name))

    def operator(self, idname, **_):
        module, name = idname.split(".")
        assert getattr(getattr(bpy.ops, module), name).get_rna_type() is not None
        self.log.append(("operator", idname))
        return SimpleNamespace()

    def label(self, text="", **_):
        self.log.append(("label", text))

    def progress(self, factor=0.0, type="BAR", text=""):
        assert 0.0 <= factor <= 1.0 and type == "BAR"
        self.log.append(("progress_text", text))
        self.log.append(("progress", factor))


def _operators(addon):
    return importlib.import_module(f"{addon.module}.operators")


def _modal_op(addon):
    class Op(_operators(addon)._RemeshOperatorMixin):
        def __init__(self):
            self.reports = []

        def report(self, kind, message):
            self.reports.append((set(kind), message))

    return Op()


def _context():
    return SimpleNamespace(window_manager=FakeWindowManager(), workspace=FakeWorkspace(),
                           window=object(), scene=bpy.context.scene, screen=None)


def _start(addon, resolution, method="mc", threads=1):
    vertices, faces = cad_part()
    obj = add_object(addon.mesh_io, "Part", vertices, faces)
    settings = addon.remesh.Settings(resolution=resolution, method=method, threads=threads,
                                     compare_mc=False)
    jobs = addon.remesh.mesh_jobs([obj], settings)
    op, context = _modal_op(addon), _context()
    before = scene_state()
    assert op.start_worker(context, addon.remesh, jobs, settings) == {"RUNNING_MODAL"}
    return op, context, before


def _status_bar(context):
    """What the status bar draws now: ``status_text_set`` got a draw function (or None)."""
    draw = context.workspace.status[-1]
    if draw is None:
        return None
    log = []
    draw(SimpleNamespace(layout=RecordingLayout(log)), bpy.context)
    return log


def test_modal_worker_progress_bar_and_finish(addon):
    run = _operators(addon).RUN
    op, context, _ = _start(addon, 48, method="sharp")
    fractions = []
    for _ in range(1200):
        result = op.modal(context, TIMER)
        if result != {"PASS_THROUGH"}:
            break
        bar = [value for kind, value in _status_bar(context) if kind == "progress"]
        assert len(bar) == 1  # a real progress bar in the status bar
        fractions.append(bar[0])
        time.sleep(0.05)
    assert result == {"FINISHED"}, op.reports
    assert "Part_Sharp" in bpy.data.objects
    assert fractions == sorted(fractions) and len(set(fractions)) >= 2
    assert any("Part: Sharp" in message for _, message in op.reports)
    assert context.workspace.status[-1] is None  # the status bar is back to normal
    assert not context.window_manager.timers and not run.active


@pytest.mark.skipif(not WEIGHTS.is_file(), reason="needs the shipped AGNDC weights")
def test_escape_stops_the_network_and_blocks_a_second_run(addon):
    """Esc while the network runs: the worker thread ends inside the network's finest scale,
    nothing is added, and until it has ended no second run can start (operators' poll, the
    Python API)."""
    run = _operators(addon).RUN
    op, context, before = _start(addon, 128, method="agndc")
    deadline = time.perf_counter() + 120
    while "scale 0" not in run.message:  # inside the finest scale: the longest single step
        assert op._thread.is_alive() and time.perf_counter() < deadline, run.message
        assert op.modal(context, TIMER) == {"PASS_THROUGH"}
        time.sleep(0.05)
    # one run at a time: the buttons are disabled and scripts are refused
    assert not bpy.ops.object.agndc_remesh.poll()
    assert not bpy.ops.import_mesh.agndc_grid.poll()
    with pytest.raises(RuntimeError, match="running"):
        bpy.ops.object.agndc_remesh(method="mc", resolution=16)
    with pytest.raises(addon.core.errors.AGNDCError, match="Another AGNDC remesh is running"):
        addon.remesh.remesh_object(bpy.data.objects["Part"],
                                   addon.remesh.Settings(method="mc", resolution=16))
    pressed = time.perf_counter()
    assert op.modal(context, ESC) == {"RUNNING_MODAL"}  # waits for the worker to stop
    assert any(kind == "label" and "Cancelling" in text
               for kind, text in _status_bar(context))
    op._thread.join(60)
    assert not op._thread.is_alive()
    stopped = time.perf_counter() - pressed
    # stopped inside the finest scale, not at its end: the worker's last progress message is
    # still that stage's (how long it took is a benchmark's business: bench_cancel_stages.py)
    assert "network scale 0" in run.message, run.message
    assert op.modal(context, TIMER) == {"CANCELLED"}
    assert scene_state() == before
    assert not run.active and bpy.ops.object.agndc_remesh.poll()
    print(f"Esc at 128³ (AGNDC, 1 thread): worker stopped after {stopped:.3f} s")


def test_draw_functions(addon):
    panels = importlib.import_module(f"{addon.module}.panels")
    vertices, faces = cad_part()
    add_object(addon.mesh_io, "Part", vertices, faces)
    log = []
    fake = SimpleNamespace(layout=RecordingLayout(log))
    panels.VIEW3D_PT_agndc_remesh.draw(fake, bpy.context)
    for _, draw in panels.MENU_HOOKS:
        draw(fake, bpy.context)
    props = [name for kind, name in log if kind == "prop"]
    assert props == ["method", "normal_filter", "low_poly", "low_poly_mode", "max_error",
                     "size_mode", "resolution", "use_modifiers", "output", "compare_mc",
                     "quads", "smooth", "threads"]
    labels = [text for kind, text in log if kind == "label"]
    (grid,) = [re.fullmatch(r"Part: (\d+) × (\d+) × (\d+) voxels", t) for t in labels
               if t.startswith("Part: ")]
    assert max(map(int, grid.groups())) == 64  # the default: 64 voxels on the longest side
    assert any(text.startswith("Estimated time: ") for text in labels)
    operators = [name for kind, name in log if kind == "operator"]
    assert operators.count("object.agndc_remesh") == 3  # sidebar, Object Data, Object menu
    assert operators.count("import_mesh.agndc_grid") == 2  # sidebar, File > Import


def test_sidebar_shows_the_progress_of_a_run(addon):
    operators, panels = _operators(addon), importlib.import_module(f"{addon.module}.panels")
    operators.RUN.begin(object(), "Sharp")
    try:
        operators.RUN.fraction, operators.RUN.message = 0.42, "Part: exact intersections"
        log = []
        panels.VIEW3D_PT_agndc_remesh.draw(SimpleNamespace(layout=RecordingLayout(log)),
                                           bpy.context)
        assert ("progress", 0.42) in log and ("label", "Part: exact intersections") in log
        assert ("progress_text", "Sharp 42%") in log  # the method, as in the status bar
        assert not bpy.ops.object.agndc_remesh.poll()
    finally:
        operators.RUN.end()


def test_operator_tooltips_are_one_line(addon):
    for operator in (bpy.ops.object.agndc_remesh, bpy.ops.import_mesh.agndc_grid):
        description = operator.get_rna_type().description
        assert description and "\n" not in description and "  " not in description


def test_no_time_estimate_for_an_object_that_cannot_run(addon):
    panels = importlib.import_module(f"{addon.module}.panels")
    bpy.ops.mesh.primitive_cube_add(size=2.0)
    settings = bpy.context.scene.agndc
    settings.size_mode, settings.voxel_size = "VOXEL_SIZE", 1e-4  # far too fine
    try:
        log = []
        panels._draw_preview(RecordingLayout(log), bpy.context, settings)
        labels = [text for kind, text in log if kind == "label"]
        assert any("at least" in text for text in labels)
        assert not any(text.startswith("Estimated time") for text in labels)
    finally:
        settings.property_unset("voxel_size")
        settings.property_unset("size_mode")


def test_status_bar_names_the_running_method(addon):
    """A Sharp or MC run is not announced as AGNDC."""
    operators = _operators(addon)
    for label in ("Sharp", "MC", "AGNDC"):
        operators.RUN.begin(object(), label)
        try:
            operators.RUN.fraction, operators.RUN.message = 0.5, "Part: dual contouring"
            log = []
            operators.draw_status(SimpleNamespace(layout=RecordingLayout(log)), bpy.context)
            texts = [text for kind, text in log if kind == "progress_text"]
            assert texts == [f"{label} 50%  Part: dual contouring"]
        finally:
            operators.RUN.end()


def test_estimate_and_confirmation(addon):
    """The grid and time shown before a run; runs estimated above 10 s ask first."""
    operators, panels = _operators(addon), importlib.import_module(f"{addon.module}.panels")
    bpy.ops.mesh.primitive_cube_add(size=2.0)
    cube = bpy.context.object
    settings = bpy.context.scene.agndc
    settings.size_mode, settings.voxel_size, settings.method = "VOXEL_SIZE", 0.05, "agndc"
    shape, quick, problem = panels.preview(cube, settings, bpy.context)
    assert shape == (42, 42, 42) and problem == "" and 0 < quick < 10
    settings.voxel_size = 2 / 254  # 256³
    shape, slow, _ = panels.preview(cube, settings, bpy.context)
    assert shape == (256, 256, 256) and slow > 10 * quick
    settings.voxel_size = 1e-4
    assert "at least" in panels.preview(cube, settings, bpy.context)[2]
    remesh = addon.remesh
    jobs = remesh.mesh_jobs([cube], remesh.Settings(method="agndc", voxel_size=0.05))
    assert operators.confirm_message(jobs) == ""
    jobs = remesh.mesh_jobs([cube], remesh.Settings(method="agndc", voxel_size=2 / 254))
    message = operators.confirm_message(jobs)
    assert message.startswith("1 object (Cube 256×256×256): about ") and "Esc cancels" in message
    assert abs(jobs[0].estimate - slow) / slow < 0.2  # the panel and the operator agree


def test_grid_imports_estimate_and_ask_first(addon, tmp_path):
    """A grid file is read when its job is made: its size gives the estimate, and an import
    estimated above 10 s asks first, as a mesh run does (the grid is read once)."""
    operators = _operators(addon)
    remesh = addon.remesh
    x, y, z = np.meshgrid(*[np.arange(200)] * 3, indexing="ij")
    big = ((x - 99.5) ** 2 + (y - 99.5) ** 2 + (z - 99.5) ** 2) < 90 ** 2
    np.save(tmp_path / "big.npy", big)
    np.save(tmp_path / "small.npy", big[::10, ::10, ::10])
    settings = remesh.Settings(method="agndc")
    small = remesh.grid_jobs([tmp_path / "small.npy"], settings)
    assert small[0].shape == (20, 20, 20) and 0 < small[0].estimate < 10
    assert operators.confirm_message(small) == ""
    jobs = remesh.grid_jobs([tmp_path / "big.npy"], settings)
    assert jobs[0].grid is not None and jobs[0].estimate > 10
    message = operators.confirm_message(jobs)
    assert message.startswith("1 grid (big 200×200×200): about ") and "Esc cancels" in message
    mc = remesh.grid_jobs([tmp_path / "big.npy"], remesh.Settings(method="mc"))
    assert mc[0].estimate < jobs[0].estimate / 10


def test_help_button_opens_the_manifest_website(addon):
    panels = importlib.import_module(f"{addon.module}.panels")
    log = []
    panels.VIEW3D_PT_agndc_remesh.draw(SimpleNamespace(layout=RecordingLayout(log)), bpy.context)
    assert ("operator", "wm.url_open") in log or not panels.help_url()
    panels.help_url.cache_clear()
    original = panels.help_url
    panels.help_url = lambda: "https://example.org/agndc/docs/blender.md"
    try:
        log.clear()
        panels.VIEW3D_PT_agndc_remesh.draw(SimpleNamespace(layout=RecordingLayout(log)),
                                           bpy.context)
        assert ("operator", "wm.url_open") in log
    finally:
        panels.help_url = original


def test_help_opens_the_shipped_user_guide(addon):
    """Without a website the Help button still helps: the guide travels inside the extension
    and opens offline (background mode has no window, so it is read into a Text datablock)."""
    panels = importlib.import_module(f"{addon.module}.panels")
    operators = importlib.import_module(f"{addon.module}.operators")
    log = []
    panels.VIEW3D_PT_agndc_remesh.draw(SimpleNamespace(layout=RecordingLayout(log)), bpy.context)
    assert ("operator", "wm.agndc_user_guide") in log
    assert operators.user_guide_path().parent.name == addon.module.rsplit(".", 1)[-1]
    assert bpy.ops.wm.agndc_user_guide() == {"FINISHED"}
    guide = bpy.data.texts[operators.USER_GUIDE_TEXT].as_string()
    assert guide.startswith("# AGNDC Remesher in Blender") and "Remesh with AGNDC" in guide
    assert bpy.ops.wm.agndc_user_guide() == {"FINISHED"}  # a second press reuses it
    assert len([t for t in bpy.data.texts if t.name.startswith(operators.USER_GUIDE_TEXT)]) == 1


def test_drag_and_drop_handler(addon):
    handler = bpy.types.AGNDC_FH_voxel_grid
    assert handler.bl_import_operator == "import_mesh.agndc_grid"
    assert set(handler.bl_file_extensions.split(";")) == {".npy", ".npz", ".binvox", ".vox",
                                                          ".nii", ".nii.gz"}
    assert handler.poll_drop(SimpleNamespace(area=SimpleNamespace(type="VIEW_3D")))
    assert not handler.poll_drop(SimpleNamespace(area=SimpleNamespace(type="PROPERTIES")))
    rna = bpy.ops.import_mesh.agndc_grid.get_rna_type()
    assert {"directory", "files", "filepath"} <= set(rna.properties.keys())


def test_grid_preview_has_no_numbers_for_non_meshes(addon):
    panels = importlib.import_module(f"{addon.module}.panels")
    bpy.ops.object.camera_add()
    log = []
    panels._draw_preview(RecordingLayout(log), bpy.context, bpy.context.scene.agndc)
    assert log == [("label", "Select mesh objects to remesh")]


def test_run_summary_names_each_input_once_and_no_warning_of_a_failure(addon):
    remesh = addon.remesh
    failed = remesh.Report(source="pair", made=[], error="pair.vox: no model 3; the file holds 2",
                           warnings=["pair is not closed: remeshed as the solid it encloses"])
    level, text = remesh.summarize([failed])
    assert level == "ERROR"
    assert text == "0 remeshed, 1 failed: pair: no model 3; the file holds 2"
    quoted = remesh.Report(source="Plane", made=[], error="'Plane': open surface")
    assert remesh.summarize([quoted])[1] == "0 remeshed, 1 failed: Plane: open surface"
    other = remesh.Report(source="Cube", made=[], error="Sphere.npy: not found")
    assert "Cube: Sphere.npy: not found" in remesh.summarize([other])[1]  # another name stays


@pytest.mark.parametrize("size", [200.0, 0.18])
def test_the_default_size_fits_millimetres_and_tiny_models(addon, size):
    """By default every object gets 64 voxels on its longest side, whatever its units."""
    remesh = addon.remesh
    bpy.ops.mesh.primitive_cube_add(size=size)
    settings = bpy.context.scene.agndc
    assert settings.size_mode == "RESOLUTION"
    (job,) = remesh.mesh_jobs([bpy.context.object], remesh.Settings(method="mc"))
    assert job.error is None and max(job.shape) == 64 and not job.warnings


def test_a_coarse_grid_warns(addon):
    remesh = addon.remesh
    bpy.ops.mesh.primitive_cube_add(size=0.18)
    (job,) = remesh.mesh_jobs([bpy.context.object], remesh.Settings(method="mc",
                                                                     voxel_size=0.05))
    assert job.error is None and max(job.shape) < 16
    assert any("voxels along its longest side" in w and "at most" in w for w in job.warnings)


def test_a_distance_within_sampling_noise_is_not_given_as_a_number(addon):
    """The report's Chamfer distance is compared with the source against itself (independent
    samples): below twice that it is noise, and the report says so instead of a number."""
    remesh = addon.remesh
    close = remesh.Report(source="Part", made=[remesh.Made(None, "agndc", 100, 1.0, 5.4e-5,
                                                           5.2e-5)])
    assert "CD within sampling noise (< 10.40e-5)" in close.summary()
    far = remesh.Report(source="Part", made=[remesh.Made(None, "mc", 100, 1.0, 20e-5, 5.2e-5)])
    assert "CD 20.00e-5" in far.summary()


def test_moving_an_object_keeps_its_cached_estimate(addon):
    """The sidebar's grid and time do not depend on where the object is or how it is turned:
    moving it reuses the cached preview; scaling it computes a new one."""
    panels = importlib.import_module(f"{addon.module}.panels")
    bpy.ops.mesh.primitive_cube_add(size=2.0)
    cube, settings = bpy.context.object, bpy.context.scene.agndc
    panels._preview_cache.clear()
    first = panels.preview(cube, settings, bpy.context)
    cube.location = (5.0, -3.0, 2.0)
    cube.rotation_euler = (0.3, 0.2, 0.1)
    bpy.context.view_layer.update()
    assert panels.preview(cube, settings, bpy.context) is first and len(panels._preview_cache) == 1
    cube.scale = (2.0, 1.0, 1.0)
    bpy.context.view_layer.update()
    assert panels.preview(cube, settings, bpy.context) is not first
