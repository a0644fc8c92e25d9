"""Operators: thin UI over ``remesh.py``.

``execute()`` runs synchronously (background mode, scripting, the redo panel). In the interface
``invoke()`` checks the selection, shows the estimated time (asking first above
``plan.CONFIRM_SECONDS``), then runs the computation on a worker thread and stays modal: a
progress bar in the status bar and the sidebar, Esc cancels (the network stops within a fraction
of a second, see ``agndc_core.inference``), and the new objects are added on the main thread at
the end (one undo step). One run at a time: both operators' ``poll()`` is False while one runs.

Every input succeeds or fails on its own; one summary report ends the run ("2 remeshed, 1
failed: ..."); the operator cancels (scene unchanged) only when every input failed.
"""

import os
import threading
import time
import traceback
from pathlib import Path

import bpy
from bpy.props import BoolProperty, CollectionProperty, EnumProperty, IntProperty, StringProperty
from bpy.types import OperatorFileListElement
from bpy_extras.io_utils import ImportHelper

from . import preferences
from .properties import (
    GRID_METHOD_ITEMS,
    OPERATOR,
    VOX_ITEMS,
    compare_mc_property,
    low_poly_mode_property,
    low_poly_property,
    max_error_property,
    method_property,
    normal_filter_property,
    output_property,
    quads_property,
    resolution_property,
    size_mode_property,
    smooth_property,
    target_faces_property,
    threads_property,
    use_modifiers_property,
    voxel_size_property,
)

#: names shared by the operator properties and the scene settings
SETTING_NAMES = ("size_mode", "voxel_size", "resolution", "method", "normal_filter",
                 "use_modifiers", "output", "compare_mc", "quads", "smooth", "threads",
                 "low_poly", "low_poly_mode", "max_error", "target_faces")
GRID_EXTENSIONS = (".npy", ".npz", ".binvox", ".vox", ".nii", ".nii.gz")
GRID_FILTER = ";".join(f"*{ext}" for ext in GRID_EXTENSIONS)
#: seconds between modal updates (progress bar, status bar, worker check)
TIMER_STEP = 0.1


class CoreMissingError(RuntimeError):
    """agndc_core or one of its dependencies (scipy, scikit-image...) cannot be imported."""


class RunState:
    """The one background run: its operator, progress and message (read by the panel and the
    status bar, written by the worker thread: plain attribute writes)."""

    def __init__(self):
        self.operator = None
        self.fraction, self.message, self.started = 0.0, "", 0.0
        self.label = "AGNDC"  # the running method's name, for the status bar
        self.cancelling = False

    @property
    def active(self) -> bool:
        return self.operator is not None

    def begin(self, operator, label: str = "AGNDC"):
        self.operator, self.fraction, self.message, self.label = operator, 0.0, "starting", label
        self.started, self.cancelling = time.perf_counter(), False

    def end(self):
        self.operator = None
        self.cancelling = False


RUN = RunState()


def _backend():
    """The ``remesh`` module, imported on first use so enabling the add-on stays fast."""
    try:
        from . import remesh
    except ImportError as exc:
        raise CoreMissingError(f"AGNDC cannot load its core library ({exc}). Install the AGNDC "
                               "extension zip built for your platform.") from exc
    return remesh


def format_seconds(seconds: float) -> str:
    """'about 40 s' / 'about 3 min' (estimates are rough: see plan.CALIBRATION)."""
    if seconds < 1:
        return "under a second"
    if seconds < 90:
        return f"about {seconds:.0f} s"
    return f"about {seconds / 60:.0f} min"


def confirm_message(jobs) -> str:
    """What to ask before a run estimated above ``plan.CONFIRM_SECONDS``; "" for a short one."""
    from ._core import plan

    ready = [job for job in jobs if job.error is None]
    seconds = sum(job.estimate for job in ready)
    if seconds <= plan.CONFIRM_SECONDS:
        return ""
    grids = ", ".join(f"{job.name} {'×'.join(map(str, job.shape))}" for job in ready[:4])
    more = f" and {len(ready) - 4} more" if len(ready) > 4 else ""
    kind = "grid" if all(job.grid_path is not None for job in ready) else "object"
    return (f"{len(ready)} {kind}{'s' * (len(ready) != 1)} ({grids}{more}): "
            f"{format_seconds(seconds)}. Esc cancels while it runs.")


def status_text(label: str, fraction: float, message: str) -> str:
    """The status bar's text during a run: 'AGNDC 42%  Part: predict'."""
    return f"{label} {fraction:.0%}  {message}"


def draw_status(header, context):
    """The status bar while a run is going (``WorkSpace.status_text_set`` takes a function)."""
    layout = header.layout
    row = layout.row(align=True)
    row.progress(factor=RUN.fraction, type="BAR",
                 text=status_text(RUN.label, RUN.fraction, RUN.message))
    layout.label(text="Cancelling..." if RUN.cancelling else "Esc: cancel", icon="CANCEL")


class _RemeshOperatorMixin:
    """Settings, reporting and the modal worker shared by both operators."""

    _timer = None

    @classmethod
    def _poll_idle(cls, context) -> bool:
        if RUN.active:
            cls.poll_message_set("An AGNDC remesh is running (Esc cancels it)")
            return False
        if context.mode != "OBJECT":
            cls.poll_message_set("Switch to Object Mode")
            return False
        return True

    def settings(self, context, remesh):
        """remesh.Settings from the operator's own properties, else the scene's settings."""
        scene_settings = getattr(context.scene, "agndc", None)
        props = self.properties
        given = {name for name in SETTING_NAMES
                 if name in props.bl_rna.properties and props.is_property_set(name)}
        values = {}
        for name in SETTING_NAMES:
            if name not in props.bl_rna.properties:
                continue
            if name in given or scene_settings is None:
                values[name] = getattr(self, name)
                continue
            value = getattr(scene_settings, name)
            items = props.bl_rna.properties[name]
            if items.type == "ENUM" and value not in items.enum_items.keys():
                value = items.default  # e.g. Sharp in the scene, but grids have no Sharp
            values[name] = value
            setattr(self, name, value)  # shown in the redo panel
        if "size_mode" in values and "size_mode" not in given:
            # a script that gives only one of the two means that one
            if "resolution" in given and "voxel_size" not in given:
                values["size_mode"] = self.size_mode = "RESOLUTION"
            elif "voxel_size" in given:
                values["size_mode"] = self.size_mode = "VOXEL_SIZE"
        prefs = preferences.get(context)
        threads = values["threads"]
        if prefs is not None and threads == 0:
            threads = prefs.default_threads
        return remesh.Settings(
            resolution=values.get("resolution", 64),
            voxel_size=values["voxel_size"] if values.get("size_mode") == "VOXEL_SIZE" else 0.0,
            method=values["method"], threads=threads,
            normal_filter=values["normal_filter"],
            **low_poly_settings(values),
            compare_mc=values["compare_mc"], smooth=values["smooth"], quads=values["quads"],
            use_modifiers=values.get("use_modifiers", True),
            replace_source=values.get("output") == "REPLACE",
            checkpoint=(prefs.checkpoint or None) if prefs is not None else None,
            model_index=self._model_index(remesh), colors=getattr(self, "colors", True))

    def _model_index(self, remesh) -> int:
        return 0

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

    def run(self, context, remesh, jobs, settings, modal: bool) -> set:
        """Compute (here or on the worker) unless every job already failed, then finish."""
        if modal and any(job.error is None for job in jobs):
            return self.start_worker(context, remesh, jobs, settings)
        try:
            remesh.compute_jobs(jobs, settings)
        except Exception as exc:
            return self.handle(exc)
        return self.finish(context, remesh, jobs, settings)

    def finish(self, context, remesh, jobs, settings) -> set:
        reports = remesh.apply_jobs(jobs, settings, context.scene)
        for report in reports:
            if report.made:
                self.report({"INFO"}, report.summary())
        level, text = remesh.summarize(reports)
        self.report({level}, text)
        return {"FINISHED"} if any(report.made for report in reports) else {"CANCELLED"}

    # ---- modal worker ----------------------------------------------------------------------

    def start_worker(self, context, remesh, jobs, settings) -> set:
        self._remesh, self._jobs, self._settings = remesh, jobs, settings
        self._cancel = threading.Event()
        self._error = None
        self._thread = threading.Thread(target=self._work, daemon=True, name="agndc-remesh")
        wm = context.window_manager
        self._timer = wm.event_timer_add(TIMER_STEP, window=context.window)
        wm.modal_handler_add(self)
        RUN.begin(self, remesh.SUFFIXES.get(settings.method, "AGNDC"))
        self._redraw(context)
        self._thread.start()
        return {"RUNNING_MODAL"}

    def _work(self):
        try:
            self._remesh.compute_jobs(self._jobs, self._settings, self._on_progress,
                                      self._cancel)
        except BaseException as exc:  # reported on the main thread by modal()
            self._error = exc

    @staticmethod
    def _on_progress(fraction, message):
        RUN.fraction, RUN.message = float(fraction), message

    def modal(self, context, event):
        if event.type == "ESC" and event.value == "PRESS":
            # the worker stops at its next check (well under a second, see inference.py); the
            # operator ends once it has, so no second run can start beside it
            self._cancel.set()
            RUN.cancelling = True
            self._redraw(context)
            return {"RUNNING_MODAL"}
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        self._redraw(context)
        if self._thread.is_alive():
            return {"PASS_THROUGH"}
        self._end(context)
        errors = self._remesh.errors
        if self._cancel.is_set() or isinstance(self._error, errors.CancelledError):
            self.report({"WARNING"}, f"{RUN.label} remesh cancelled: nothing was added")
            return {"CANCELLED"}
        if isinstance(self._error, errors.AGNDCError):
            return self.fail(self._error)
        if self._error is not None:  # a bug: show it, keep the traceback in the console
            traceback.print_exception(self._error)
            return self.fail(f"AGNDC internal error: {self._error!r} (see the system console)")
        return self.finish(context, self._remesh, self._jobs, self._settings)

    def cancel(self, context):
        """Blender aborts the modal operator (file load, window closed): stop the worker."""
        self._cancel.set()
        self._thread.join(5.0)
        self._end(context)

    def _redraw(self, context):
        if context.workspace is not None:
            context.workspace.status_text_set(draw_status if RUN.active else None)
        screen = getattr(context, "screen", None)
        for area in getattr(screen, "areas", ()):
            if area.type == "VIEW_3D":
                area.tag_redraw()

    def _end(self, context):
        if self._timer is not None:
            context.window_manager.event_timer_remove(self._timer)
            self._timer = None
        RUN.end()
        self._redraw(context)


class OBJECT_OT_agndc_remesh(_RemeshOperatorMixin, bpy.types.Operator):
    """Rebuild the selected meshes from a voxel grid of each (AGNDC, UNDC, marching cubes or
    sharp dual contouring); the sources are kept"""

    bl_idname = "object.agndc_remesh"
    bl_label = "Remesh with AGNDC"
    bl_options = {"REGISTER", "UNDO"}

    size_mode: size_mode_property(**OPERATOR)
    voxel_size: voxel_size_property(**OPERATOR)
    resolution: resolution_property(**OPERATOR)
    method: method_property(**OPERATOR)
    normal_filter: normal_filter_property(**OPERATOR)
    low_poly: low_poly_property(**OPERATOR)
    low_poly_mode: low_poly_mode_property(**OPERATOR)
    max_error: max_error_property(**OPERATOR)
    target_faces: target_faces_property(**OPERATOR)
    use_modifiers: use_modifiers_property(**OPERATOR)
    output: output_property(**OPERATOR)
    compare_mc: compare_mc_property(**OPERATOR)
    quads: quads_property(**OPERATOR)
    smooth: smooth_property(**OPERATOR)
    threads: threads_property(**OPERATOR)
    use_modal: BoolProperty(default=False, options={"HIDDEN", "SKIP_SAVE"})

    @classmethod
    def poll(cls, context):
        if not cls._poll_idle(context):
            return False
        if not any(obj.type == "MESH" for obj in context.selected_objects):
            cls.poll_message_set("Select one or more mesh objects")
            return False
        return True

    def _prepare(self, context):
        remesh = _backend()
        settings = self.settings(context, remesh)
        return remesh, settings, remesh.mesh_jobs(context.selected_objects, settings)

    def execute(self, context):
        modal = self.use_modal and context.window is not None and not bpy.app.background
        self.use_modal = False  # the redo panel reruns synchronously
        try:
            remesh, settings, jobs = self._prepare(context)
        except Exception as exc:
            return self.handle(exc)
        return self.run(context, remesh, jobs, settings, modal)

    def invoke(self, context, event):
        if bpy.app.background or context.window is None:
            return self.execute(context)
        try:
            _, _, jobs = self._prepare(context)
        except Exception as exc:
            return self.handle(exc)
        self.use_modal = True
        message = confirm_message(jobs)
        if message:
            return context.window_manager.invoke_confirm(
                self, event, title="Remesh with AGNDC", message=message, confirm_text="Remesh",
                icon="WARNING")
        return self.execute(context)

    def draw(self, context):
        draw_settings(self.layout, self, mesh=True)


class IMPORT_MESH_OT_agndc_grid(_RemeshOperatorMixin, bpy.types.Operator, ImportHelper):
    """Reconstruct voxel grids (.npy .npz .binvox .vox .nii .nii.gz) as meshes (AGNDC, UNDC or
    marching cubes); several files, and drag and drop into the 3D Viewport"""

    bl_idname = "import_mesh.agndc_grid"
    bl_label = "Import Voxel Grid (AGNDC)"
    bl_options = {"REGISTER", "UNDO"}

    filter_glob: StringProperty(default=GRID_FILTER, options={"HIDDEN"})
    directory: StringProperty(subtype="DIR_PATH", options={"HIDDEN", "SKIP_SAVE"})
    files: CollectionProperty(type=OperatorFileListElement, options={"HIDDEN", "SKIP_SAVE"})
    method: method_property(GRID_METHOD_ITEMS, **OPERATOR)
    normal_filter: normal_filter_property(**OPERATOR)
    low_poly: low_poly_property(**OPERATOR)
    low_poly_mode: low_poly_mode_property(**OPERATOR)
    max_error: max_error_property(**OPERATOR)
    target_faces: target_faces_property(**OPERATOR)
    compare_mc: compare_mc_property(**OPERATOR)
    quads: quads_property(**OPERATOR)
    smooth: smooth_property(**OPERATOR)
    threads: threads_property(**OPERATOR)
    vox_models: EnumProperty(name=".vox Models", items=VOX_ITEMS, default="INDEX",
                             description="MagicaVoxel files can hold several models")
    model_index: IntProperty(name="Model Index", description="Which model of a .vox file "
                             "(0 = the first)", default=0, min=0, max=10_000,
                             options={"SKIP_SAVE"})
    colors: BoolProperty(name="Voxel Colors", default=True,
                         description="Coloured grids (MagicaVoxel .vox): one material per "
                         "palette color, each face colored by the nearest voxel")
    per_label: BoolProperty(name="Per Label", default=False,
                            description="Label maps (.nii .nii.gz .npy .npz): one object per "
                            "label (each positive value), named <file>_label-<value>, in place; "
                            "off: every label merged into one solid")
    labels: StringProperty(name="Labels", default="",
                           description="Only these labels, e.g. 1,3,7 (empty: every label)")
    use_modal: BoolProperty(default=False, options={"HIDDEN", "SKIP_SAVE"})
    # set on the second call of a long import: ask (invoke) or run (execute) without asking again
    confirm: BoolProperty(default=False, options={"HIDDEN", "SKIP_SAVE"})

    @classmethod
    def poll(cls, context):
        return cls._poll_idle(context)

    def _model_index(self, remesh) -> int:
        return remesh.ALL_MODELS if self.vox_models == "ALL" else self.model_index

    def settings(self, context, remesh):
        settings = super().settings(context, remesh)
        settings.per_label, settings.labels = self.per_label, self.labels
        return settings

    def paths(self) -> list[str]:
        """The chosen files: several from the file browser or a drop, else ``filepath``."""
        names = [f.name for f in self.files if f.name]
        if names and self.directory:
            return [os.path.join(self.directory, name) for name in names]
        return [self.filepath]

    def invoke(self, context, event):
        self.use_modal = not bpy.app.background
        if self.confirm:  # a long import, asked once the files are chosen (see execute)
            try:
                remesh = _backend()
                jobs = remesh.grid_jobs(self.paths(), self.settings(context, remesh))
            except Exception as exc:
                return self.handle(exc)
            return context.window_manager.invoke_confirm(
                self, event, title="Import with AGNDC", message=confirm_message(jobs),
                confirm_text="Import", icon="WARNING")
        if self.properties.is_property_set("filepath") or self.files:  # dropped files
            popup = getattr(ImportHelper, "invoke_popup", None)
            if popup is not None:
                return popup(self, context)
            return context.window_manager.invoke_props_dialog(self)
        context.window_manager.fileselect_add(self)
        return {"RUNNING_MODAL"}

    def execute(self, context):
        modal = self.use_modal and context.window is not None and not bpy.app.background
        self.use_modal = False
        try:
            remesh = _backend()
            settings = self.settings(context, remesh)
            jobs = remesh.grid_jobs(self.paths(), settings)
        except Exception as exc:
            return self.handle(exc)
        if modal and not self.confirm and confirm_message(jobs):
            # the grids are read only now (their size gives the estimate): call this operator
            # again to ask, as a mesh run above the threshold asks before it starts
            values = self.as_keywords(ignore=("files", "filter_glob", "confirm", "use_modal"))
            bpy.ops.import_mesh.agndc_grid("INVOKE_DEFAULT", confirm=True,
                                           files=[{"name": f.name} for f in self.files],
                                           **values)
            return {"CANCELLED"}
        return self.run(context, remesh, jobs, settings, modal)

    def draw(self, context):
        draw_settings(self.layout, self, mesh=False)


#: the user guide inside the built extension (``build_addon.py`` copies docs/blender.md there),
#: or the one of a checkout
USER_GUIDES = (Path(__file__).parent / "user_guide.md",
               Path(__file__).parents[1] / "docs" / "blender.md")
#: the Text datablock the guide is read into
USER_GUIDE_TEXT = "AGNDC Remesher guide"


def user_guide_path() -> Path | None:
    return next((path for path in USER_GUIDES if path.is_file()), None)


class WM_OT_agndc_user_guide(bpy.types.Operator):
    """Open the AGNDC Remesher user guide (shipped with the extension, readable offline) in a
    Text Editor window"""

    bl_idname = "wm.agndc_user_guide"
    bl_label = "User Guide"
    bl_options = {"REGISTER"}

    def execute(self, context):
        path = user_guide_path()
        if path is None:
            self.report({"ERROR"}, "The user guide is missing from this installation")
            return {"CANCELLED"}
        text = bpy.data.texts.get(USER_GUIDE_TEXT)
        if text is None:
            text = bpy.data.texts.new(USER_GUIDE_TEXT)
            text.from_string(path.read_text(encoding="utf-8"))
        if not bpy.app.background and _show_text_in_new_window(context, text):
            return {"FINISHED"}
        self.report({"INFO"}, f"The user guide is in the Text Editor as '{text.name}'")
        return {"FINISHED"}


def _show_text_in_new_window(context, text) -> bool:
    """A new window whose one area is a Text Editor showing ``text``; False if no window
    could be opened (then the guide stays available as a Text datablock)."""
    windows = set(context.window_manager.windows)
    try:
        bpy.ops.wm.window_new()
    except RuntimeError:
        return False
    new = [window for window in context.window_manager.windows if window not in windows]
    if not new:
        return False
    area = new[0].screen.areas[0]
    area.type = "TEXT_EDITOR"
    area.spaces.active.text = text
    return True


class AGNDC_FH_voxel_grid(bpy.types.FileHandler):
    """Drag and drop of grid files into the 3D Viewport or the Outliner (Blender 4.1+)."""

    bl_idname = "AGNDC_FH_voxel_grid"
    bl_label = "Voxel Grid (AGNDC)"
    bl_import_operator = IMPORT_MESH_OT_agndc_grid.bl_idname
    bl_file_extensions = ";".join(GRID_EXTENSIONS)

    @classmethod
    def poll_drop(cls, context):
        area = context.area
        return area is not None and area.type in {"VIEW_3D", "OUTLINER"}


def low_poly_settings(values: dict) -> dict:
    """``remesh.Settings``' decimation fields from the Low Poly properties (None: off)."""
    on = values.get("low_poly", False)
    by_error = values.get("low_poly_mode") == "ERROR"
    return {"decimate_error": values["max_error"] if on and by_error else None,
            "target_faces": values["target_faces"] if on and not by_error else None}


def draw_settings(layout, data, mesh: bool) -> None:
    """The settings of ``data`` (scene settings or an operator), for the sidebar, the redo panel
    and the import dialog."""
    layout.use_property_split = True
    layout.use_property_decorate = False
    col = layout.column()
    col.prop(data, "method")
    learned = col.column()
    learned.active = data.method in ("agndc", "undc")  # the filter acts on a network's mesh
    learned.prop(data, "normal_filter")
    col.prop(data, "low_poly")
    low_poly = col.column()
    low_poly.active = data.low_poly
    low_poly.prop(data, "low_poly_mode")
    low_poly.prop(data, "max_error" if data.low_poly_mode == "ERROR" else "target_faces")
    if mesh:
        col.prop(data, "size_mode")
        col.prop(data, "voxel_size" if data.size_mode == "VOXEL_SIZE" else "resolution")
        col.prop(data, "use_modifiers")
        col.prop(data, "output")
    else:
        col.prop(data, "vox_models")
        if data.vox_models == "INDEX":
            col.prop(data, "model_index")
        col.prop(data, "colors")
        col.prop(data, "per_label")
        if data.per_label:
            col.prop(data, "labels")
    sub = col.column()
    sub.active = data.method != "mc" and not (mesh and data.output == "REPLACE")
    sub.prop(data, "compare_mc")
    quads = col.column()
    # marching cubes and a decimated mesh are triangles only
    quads.active = data.method != "mc" and not data.low_poly
    quads.prop(data, "quads")
    col.prop(data, "smooth")
    col.prop(data, "threads")
