"""AGNDC Remesher for Blender: "Remesh with AGNDC" for mesh objects and voxel-grid import,
a thin UI over the bpy-free ``agndc_core`` library.

Installs as an extension (blender_manifest.toml, Blender 4.2+) or as a legacy add-on (bl_info;
the core's dependencies must then be importable from Blender's Python)."""

bl_info = {
    "name": "AGNDC Remesher",
    "author": "AGNDC Remesher developers",
    "version": (0, 1, 0),
    "blender": (4, 2, 0),
    "location": "View3D > Sidebar > AGNDC, Object > Remesh with AGNDC, File > Import, "
                "drag and drop",
    "description": "Neural dual contouring: voxel grids and meshes to clean meshes",
    "category": "Mesh",
}

import bpy  # noqa: E402  (bl_info first, as Blender reads it)

from . import operators, panels, preferences, properties  # noqa: E402

classes = (
    preferences.AGNDC_AddonPreferences,
    properties.AGNDC_RemeshSettings,
    operators.OBJECT_OT_agndc_remesh,
    operators.IMPORT_MESH_OT_agndc_grid,
    operators.WM_OT_agndc_user_guide,
    operators.AGNDC_FH_voxel_grid,
    panels.VIEW3D_PT_agndc_remesh,
)


def register():
    for cls in classes:
        if issubclass(cls, bpy.types.Operator) and cls.__doc__:
            # the tooltip: the docstring as one line (Blender shows its line breaks and indent)
            cls.bl_description = " ".join(cls.__doc__.split())
        bpy.utils.register_class(cls)
    bpy.types.Scene.agndc = bpy.props.PointerProperty(type=properties.AGNDC_RemeshSettings)
    for type_name, draw in panels.MENU_HOOKS:
        getattr(bpy.types, type_name).append(draw)


def unregister():
    for type_name, draw in reversed(panels.MENU_HOOKS):
        getattr(bpy.types, type_name).remove(draw)
    del bpy.types.Scene.agndc
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
