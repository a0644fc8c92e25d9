"""UI: the sidebar tab (settings, the grid and time a run will take, the progress bar of a
running one, help), plus draw hooks for Object Data > Remesh, the Object menu (so F3 finds the
operator) and File > Import. Drawing only; the work is in operators.py and remesh.py."""

from functools import lru_cache
from pathlib import Path

import bpy
import numpy as np

from . import mesh_io
from .operators import (
    RUN,
    IMPORT_MESH_OT_agndc_grid,
    OBJECT_OT_agndc_remesh,
    WM_OT_agndc_user_guide,
    draw_settings,
    format_seconds,
)

#: where the manifest is: inside the built extension, or at the root of a checkout
MANIFESTS = (Path(__file__).parent / "blender_manifest.toml",
             Path(__file__).parents[1] / "blender_manifest.toml")
#: the sidebar estimates at most this many selected objects (each needs its mesh's areas)
PREVIEW_OBJECTS = 16

_preview_cache: dict = {}


class VIEW3D_PT_agndc_remesh(bpy.types.Panel):
    bl_label = "AGNDC Remesher"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "AGNDC"

    def draw(self, context):
        layout = self.layout
        settings = context.scene.agndc
        if RUN.active:
            col = layout.column(align=True)
            col.progress(factor=RUN.fraction, type="BAR", text=f"{RUN.label} {RUN.fraction:.0%}")
            col.label(text=RUN.message)
            col.label(text="Cancelling..." if RUN.cancelling else "Esc: cancel", icon="CANCEL")
        draw_settings(layout.column(), settings, mesh=True)
        _draw_preview(layout, context, settings)
        _draw_weights_status(layout, settings.method)
        col = layout.column(align=True)
        col.operator(OBJECT_OT_agndc_remesh.bl_idname, icon="MOD_REMESH")
        col.operator(IMPORT_MESH_OT_agndc_grid.bl_idname, text="Import Voxel Grid...",
                     icon="IMPORT")
        row = layout.row(align=True)
        row.operator(WM_OT_agndc_user_guide.bl_idname, icon="HELP")
        url = help_url()
        if url:
            row.operator("wm.url_open", text="Website", icon="URL").url = url


@lru_cache(maxsize=1)
def help_url() -> str:
    """The manifest's ``website`` (the one place the documentation URL is written), or "" (then
    the panel shows the shipped user guide only)."""
    import tomllib

    for path in MANIFESTS:
        if path.is_file():
            with open(path, "rb") as handle:
                return str(tomllib.load(handle).get("website", ""))
    return ""


def _draw_preview(layout, context, settings) -> None:
    """The grid each selected mesh gets and the estimated time of the run (or why it fails)."""
    meshes = [obj for obj in context.selected_objects if obj.type == "MESH"]
    if not meshes:
        layout.label(text="Select mesh objects to remesh", icon="INFO")
        return
    box = layout.box().column(align=True)
    total, runnable = 0.0, 0
    for obj in meshes[:PREVIEW_OBJECTS]:
        shape, seconds, problem = preview(obj, settings, context)
        if problem:
            box.label(text=f"{obj.name}: {problem}", icon="ERROR")
            continue
        total, runnable = total + seconds, runnable + 1
        box.label(text=f"{obj.name}: {' × '.join(map(str, shape))} voxels")
    if len(meshes) > PREVIEW_OBJECTS:
        box.label(text=f"... and {len(meshes) - PREVIEW_OBJECTS} more")
        runnable += len(meshes) - PREVIEW_OBJECTS
    if runnable:  # no time under objects that cannot run
        box.label(text=f"Estimated time: {format_seconds(total)}", icon="TIME")


def preview(obj, settings, context):
    """(grid shape, estimated seconds, problem text or "") of remeshing ``obj`` now; cached
    per object, mesh size, per-axis scale and settings, so redraws stay cheap. Moving or
    rotating the object changes neither (the grid follows the object's own axes), so dragging
    it around recomputes nothing."""
    from ._core import errors, plan
    from .remesh import estimate_run, frame_of, run_methods

    evaluated = obj.evaluated_get(context.evaluated_depsgraph_get()) \
        if settings.use_modifiers else obj
    mesh = evaluated.data
    # per-axis scale to 6 digits: a rotation's float32 noise must not count as a new scale
    scale = np.linalg.norm(np.array(obj.matrix_world)[:3, :3], axis=0)
    key = (obj.name, mesh.as_pointer(), len(mesh.vertices), len(mesh.polygons),
           tuple(f"{s:.6g}" for s in scale), settings.size_mode, settings.voxel_size,
           settings.resolution, settings.method, settings.compare_mc, settings.output,
           settings.threads)
    if key in _preview_cache:
        return _preview_cache[key]
    if len(_preview_cache) > 256:
        _preview_cache.clear()
    try:
        frame, world_per_unit = frame_of(np.array(obj.matrix_world))
        corners = mesh_io.local_box(evaluated) * frame
        extent = np.ptp(corners, axis=0) * world_per_unit
        by_size = settings.size_mode == "VOXEL_SIZE"
        grid = plan.plan_grid(extent, voxel_size=settings.voxel_size if by_size else None,
                              resolution=None if by_size else settings.resolution,
                              source=obj.name)
        # area vectors in the voxelised frame, in world units: the cofactor of the scale
        scale = frame * world_per_unit
        cofactor = np.array([scale[1] * scale[2], scale[0] * scale[2], scale[0] * scale[1]])
        crossings = plan.area_crossings(mesh_io.polygon_areas(mesh) * cofactor, grid.voxel_size)
        methods = run_methods(settings.method, settings.compare_mc, settings.output == "REPLACE")
        # the operator measures the distances of a mesh's results
        seconds = estimate_run(methods, grid.shape, crossings, settings.threads, distances=True)
        result = (grid.shape, seconds, "")
    except errors.AGNDCError as exc:
        result = ((), 0.0, str(exc).removeprefix(f"{obj.name}: "))
    _preview_cache[key] = result
    return result


def _draw_weights_status(layout, method):
    """One line saying whether the chosen model's weights are there (nothing for MC, sharp)."""
    try:
        from . import preferences, remesh
    except ImportError as exc:
        layout.label(text=f"Core library missing: {exc}", icon="ERROR")
        return
    prefs = preferences.get()
    path = remesh.checkpoint_path(method, prefs.checkpoint if prefs else None)
    if path is not None and not path.is_file():
        layout.label(text=f"No {method.upper()} weights: {path.name}", icon="ERROR")


def draw_data_remesh(self, context):
    """Appended to Properties > Object Data > Remesh, below the Voxel/Quad remeshers."""
    if context.object is not None and context.object.type == "MESH":
        self.layout.operator(OBJECT_OT_agndc_remesh.bl_idname, icon="MOD_REMESH")


def draw_object_menu(self, context):
    self.layout.separator()
    self.layout.operator(OBJECT_OT_agndc_remesh.bl_idname, icon="MOD_REMESH")


def draw_import_menu(self, context):
    self.layout.operator(IMPORT_MESH_OT_agndc_grid.bl_idname,
                         text="Voxel Grid, AGNDC (.npy .npz .binvox .vox .nii)")


#: (menu or panel type name, draw function) pairs appended on register
MENU_HOOKS = (
    ("DATA_PT_remesh", draw_data_remesh),
    ("VIEW3D_MT_object", draw_object_menu),
    ("TOPBAR_MT_file_import", draw_import_menu),
)
