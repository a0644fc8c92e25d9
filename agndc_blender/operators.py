"""Operators: thin UI over ``remesh.py``.

``execute()`` runs synchronously (background mode, scripting, the redo panel). ``invoke()`` in
the interface runs the computation on a worker thread and stays modal: progress bar and status
text, Esc cancels, and the new objects are added on the main thread at the end (one undo step).
Every ``AGNDCError`` becomes an error report and ``{'CANCELLED'}`` with the scene unchanged.
"""

import threading
import traceback

import bpy
from bpy.props import BoolProperty, StringProperty
from bpy_extras.io_utils import ImportHelper

from . import preferences
from .properties import (
    compare_mc_property,
    method_property,
    resolution_property,
    smooth_property,
    threads_property,
)

#: names shared by the operator properties, the scene settings and ``remesh.Settings``
SETTING_NAMES = ("resolution", "method", "threads", "compare_mc", "smooth")
GRID_FILTER = "*.npy;*.npz;*.binvox;*.vox;*.nii;*.nii.gz"


class CoreMissingError(RuntimeError):
    """agndc_core or one of its dependencies (torch, scipy...) cannot be imported."""


def _backend():
    """The ``remesh`` module, imported on first use so enabling the add-on stays fast."""
    try:
        from . import remesh
    except ImportError as exc:
        raise CoreMissingError(f"AGNDC cannot load its core library ({exc}). Install the AGNDC "
                               "extension zip built for your platform.") from exc
    return remesh


class _RemeshOperatorMixin:
    """Settings resolution, error reporting and the modal worker shared by both operators."""

    _running = False  # one background job at a time (class-wide)
    _timer = None

    def settings(self, context, remesh):
        """remesh.Settings from the operator's own properties, else the scene's settings."""
        scene_settings = getattr(context.scene, "agndc", None)
        values = {}
        for name in SETTING_NAMES:
            if name not in self.properties.bl_rna.properties:
                continue
            if self.properties.is_property_set(name) or scene_settings is None:
                values[name] = getattr(self, name)
            else:
                values[name] = getattr(scene_settings, name)
                setattr(self, name, values[name])  # shown in the redo panel
        prefs = preferences.get(context)
        if prefs is not None:
            if values["threads"] == 0:
                values["threads"] = prefs.default_threads
            values["checkpoint"] = prefs.checkpoint or None
        return remesh.Settings(**values)

    def fail(self, exc) -> set:
        self.report({"ERROR"}, str(exc))
        return {"CANCELLED"}

    def handle(self, exc) -> set:
        """Report a user error (AGNDCError, missing core) and cancel; re-raise a bug."""
        if isinstance(exc, CoreMissingError):
            return self.fail(exc)
        from ._core import errors

        if isinstance(exc, errors.AGNDCError):
            return self.fail(exc)
        raise exc

    def finish(self, context, remesh, jobs, settings) -> set:
        reports = remesh.apply_jobs(jobs, settings, context.scene)
        for report in reports:
            self.report({"INFO"}, report.summary())
        return {"FINISHED"}

    # ---- modal worker ----------------------------------------------------------------------

    def start_worker(self, context, remesh, jobs, settings) -> set:
        self._remesh, self._jobs, self._settings = remesh, jobs, settings
        self._cancel = threading.Event()
        self._progress = (0.0, "starting")
        self._error = None
        self._thread = threading.Thread(target=self._work, daemon=True, name="agndc-remesh")
        wm = context.window_manager
        self._timer = wm.event_timer_add(0.1, window=context.window)
        wm.modal_handler_add(self)
        wm.progress_begin(0, 100)
        type(self)._running = True
        self._thread.start()
        return {"RUNNING_MODAL"}

    def _work(self):
        try:
            self._remesh.compute_jobs(self._jobs, self._settings, self._on_progress,
                                      self._cancel)
        except BaseException as exc:  # reported on the main thread by modal()
            self._error = exc

    def _on_progress(self, fraction, message):
        self._progress = (fraction, message)

    def modal(self, context, event):
        if event.type == "ESC" and event.value == "PRESS":
            self._cancel.set()  # the worker stops at its next check and its result is dropped
            self._end(context)
            self.report({"WARNING"}, "AGNDC remesh cancelled")
            return {"CANCELLED"}
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        fraction, message = self._progress
        context.window_manager.progress_update(int(100 * fraction))
        context.workspace.status_text_set(f"AGNDC {fraction:.0%}: {message} (Esc to cancel)")
        if self._thread.is_alive():
            return {"PASS_THROUGH"}
        self._end(context)
        errors = self._remesh.errors
        if isinstance(self._error, errors.CancelledError):
            self.report({"WARNING"}, "AGNDC remesh cancelled")
            return {"CANCELLED"}
        if isinstance(self._error, errors.AGNDCError):
            return self.fail(self._error)
        if self._error is not None:  # a bug: show it, keep the traceback in the console
            traceback.print_exception(self._error)
            return self.fail(f"AGNDC internal error: {self._error!r} (see the system console)")
        return self.finish(context, self._remesh, self._jobs, self._settings)

    def cancel(self, context):
        """Blender aborts the modal operator (file load, window closed)."""
        self._cancel.set()
        self._end(context)

    def _end(self, context):
        wm = context.window_manager
        if self._timer is not None:
            wm.event_timer_remove(self._timer)
            self._timer = None
        wm.progress_end()
        if context.workspace is not None:
            context.workspace.status_text_set(None)
        type(self)._running = False


class OBJECT_OT_agndc_remesh(_RemeshOperatorMixin, bpy.types.Operator):
    """Rebuild the selected meshes with AGNDC from a voxel grid of each; the sources are kept"""

    bl_idname = "object.agndc_remesh"
    bl_label = "Remesh with AGNDC"
    bl_options = {"REGISTER", "UNDO"}

    resolution: resolution_property()
    method: method_property()
    threads: threads_property()
    compare_mc: compare_mc_property()
    smooth: smooth_property()

    @classmethod
    def poll(cls, context):
        return context.mode == "OBJECT" and not cls._running

    def _prepare(self, context):
        remesh = _backend()
        settings = self.settings(context, remesh)
        return remesh, settings, remesh.mesh_jobs(context.selected_objects, settings)

    def execute(self, context):
        try:
            remesh, settings, jobs = self._prepare(context)
            remesh.compute_jobs(jobs, settings)
        except Exception as exc:
            return self.handle(exc)
        return self.finish(context, remesh, jobs, settings)

    def invoke(self, context, event):
        if bpy.app.background or context.window is None:
            return self.execute(context)
        try:
            remesh, settings, jobs = self._prepare(context)
        except Exception as exc:
            return self.handle(exc)
        return self.start_worker(context, remesh, jobs, settings)


class IMPORT_MESH_OT_agndc_grid(_RemeshOperatorMixin, bpy.types.Operator, ImportHelper):
    """Reconstruct a voxel grid (.npy .npz .binvox .vox .nii .nii.gz) as AGNDC and MC meshes"""

    bl_idname = "import_mesh.agndc_grid"
    bl_label = "Import Voxel Grid (AGNDC)"
    bl_options = {"REGISTER", "UNDO"}

    filter_glob: StringProperty(default=GRID_FILTER, options={"HIDDEN"})
    method: method_property()
    threads: threads_property()
    compare_mc: compare_mc_property()
    smooth: smooth_property()
    use_modal: BoolProperty(default=False, options={"HIDDEN", "SKIP_SAVE"})

    @classmethod
    def poll(cls, context):
        return context.mode == "OBJECT" and not cls._running

    def invoke(self, context, event):
        self.use_modal = not bpy.app.background
        return ImportHelper.invoke(self, context, event)

    def execute(self, context):
        try:
            remesh = _backend()
            settings = self.settings(context, remesh)
            jobs = [remesh.grid_job(self.filepath, settings)]
            if self.use_modal and context.window is not None:
                return self.start_worker(context, remesh, jobs, settings)
            remesh.compute_jobs(jobs, settings)
        except Exception as exc:
            return self.handle(exc)
        return self.finish(context, remesh, jobs, settings)

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        for name in ("method", "compare_mc", "threads", "smooth"):
            layout.prop(self, name)

