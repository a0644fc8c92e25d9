"""UI: the sidebar tab, plus draw hooks for Object Data > Remesh, the Object menu (so F3 finds
the operator) and File > Import. Drawing only; the work is in operators.py."""

import bpy

from .operators import IMPORT_MESH_OT_agndc_grid, OBJECT_OT_agndc_remesh


class VIEW3D_PT_agndc_remesh(bpy.types.Panel):
    bl_label = "AGNDC Remesher"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "AGNDC"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        settings = context.scene.agndc
        col = layout.column()
        col.prop(settings, "resolution")
        col.prop(settings, "method")
        col.prop(settings, "threads")
        col.prop(settings, "compare_mc")
        col.prop(settings, "smooth")
        _draw_weights_status(layout, settings.method)
        col = layout.column(align=True)
        col.operator(OBJECT_OT_agndc_remesh.bl_idname, icon="MOD_REMESH")
        col.operator(IMPORT_MESH_OT_agndc_grid.bl_idname, text="Import Voxel Grid...",
                     icon="IMPORT")


def _draw_weights_status(layout, method):
    """One line saying whether the chosen model's weights are there (nothing for MC)."""
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
