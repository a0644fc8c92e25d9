"""The interactive parts that background mode cannot drive: the modal worker (with a stand-in
window manager and events) and the draw functions (with a recording layout)."""

import importlib
import time
from types import SimpleNamespace

import bpy
import pytest
from helpers import add_object, cad_part, scene_state

pytestmark = pytest.mark.blender


class FakeWindowManager:
    def __init__(self):
        self.progress, self.handlers, self.timers = [], [], []

    def event_timer_add(self, step, window=None):
        self.timers.append(object())
        return self.timers[-1]

    def event_timer_remove(self, timer):
        self.timers.remove(timer)

    def modal_handler_add(self, op):
        self.handlers.append(op)

    def progress_begin(self, lo, hi):
        self.progress.append("begin")

    def progress_update(self, value):
        self.progress.append(value)

    def progress_end(self):
        self.progress.append("end")


class FakeWorkspace:
    def __init__(self):
        self.status = []

    def status_text_set(self, text):
        self.status.append(text)


def _modal_op(addon):
    operators = importlib.import_module(f"{addon.module}.operators")

    class Op(operators._RemeshOperatorMixin):
        def __init__(self):
            self.reports = []

        def report(self, kind, message):
            self.reports.append((set(kind), message))

    return Op()


def _context():
    return SimpleNamespace(window_manager=FakeWindowManager(), workspace=FakeWorkspace(),
                           window=object(), scene=bpy.context.scene)


def _start(addon, resolution):
    vertices, faces = cad_part()
    obj = add_object(addon.mesh_io, "Part", vertices, faces)
    settings = addon.remesh.Settings(resolution=resolution, method="mc")
    jobs = addon.remesh.mesh_jobs([obj], settings)
    op, context = _modal_op(addon), _context()
    before = scene_state()
    assert op.start_worker(context, addon.remesh, jobs, settings) == {"RUNNING_MODAL"}
    return op, context, before


def test_modal_worker_finishes_on_the_main_thread(addon):
    op, context, _ = _start(addon, 32)
    timer = SimpleNamespace(type="TIMER", value="NOTHING")
    for _ in range(600):
        result = op.modal(context, timer)
        if result != {"PASS_THROUGH"}:
            break
        time.sleep(0.05)
    assert result == {"FINISHED"}, op.reports
    assert "Part_MC" in bpy.data.objects
    assert any("Part: MC" in message for _, message in op.reports)
    wm = context.window_manager
    assert wm.progress[0] == "begin" and wm.progress[-1] == "end" and not wm.timers
    assert context.workspace.status[-1] is None  # status text cleared
    assert not type(op)._running


def test_modal_escape_cancels_and_leaves_scene(addon):
    op, context, before = _start(addon, 200)
    assert op.modal(context, SimpleNamespace(type="ESC", value="PRESS")) == {"CANCELLED"}
    assert op._cancel.is_set()
    op._thread.join(60)  # the worker notices at its next check
    assert not op._thread.is_alive()
    assert scene_state() == before
    assert context.window_manager.progress[-1] == "end" and not context.window_manager.timers
    assert not type(op)._running


class RecordingLayout:
    """Enough of UILayout for the draw functions; checks every prop name exists."""

    def __init__(self, log):
        self.log = log
        self.use_property_split = self.use_property_decorate = False

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

    def label(self, text="", **_):
        self.log.append(("label", text))


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
    assert props == ["resolution", "method", "threads", "compare_mc", "smooth"]
    operators = [name for kind, name in log if kind == "operator"]
    assert operators.count("object.agndc_remesh") == 3  # sidebar, Object Data, Object menu
    assert operators.count("import_mesh.agndc_grid") == 2  # sidebar, File > Import
