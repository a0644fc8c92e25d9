"""Settings shared by the sidebar, the Object Data > Remesh button and the operators: one
PropertyGroup behind ``Scene.agndc``. Operator properties of the same names override them.

Limits are the core's (``agndc_core.plan``), as hard limits, so a value the core would refuse
cannot be typed."""

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty

from ._core import methods, plan

RESOLUTION_MIN, RESOLUTION_DEFAULT, RESOLUTION_MAX = plan.RESOLUTION_MIN, 64, plan.RESOLUTION_MAX
#: default voxel size in world units: the default 2 m cube becomes a 42³ grid
VOXEL_SIZE_DEFAULT = 0.05
#: smallest voxel size that can be typed; finer sizes still fail per object against
#: RESOLUTION_MAX and grid.MAX_VOXELS, with a message naming the size that works
VOXEL_SIZE_MIN = 1e-5

#: the add-on's methods, from the core's registry (``agndc_core/methods.py``)
METHOD_ITEMS = tuple((m.name, methods.title(m.name), m.description)
                     for m in methods.REGISTRY if m.in_blender)
#: methods of the grid importer: a grid alone has no exact surface to contour
GRID_METHOD_ITEMS = tuple(item for item in METHOD_ITEMS
                          if not methods.BY_NAME[item[0]].mesh_only)

SIZE_MODE_ITEMS = (
    ("VOXEL_SIZE", "Voxel Size", "Voxel edge in world units, as in Blender's Voxel Remesh"),
    ("RESOLUTION", "Resolution", "Voxels along the longest side of each object"),
)

OUTPUT_ITEMS = (
    ("BESIDE", "Beside Source",
     "New objects beside the source, in the 'AGNDC Results' collection; the source stays"),
    ("REPLACE", "Replace Source",
     "The result takes the source's place (same transform, parent and collections); the source "
     "is hidden, not deleted (Ctrl Z undoes)"),
)

LOW_POLY_ITEMS = (
    ("ERROR", "Max Error", "Decimate as far as the surface moves by at most Max Error voxels"),
    ("FACES", "Target Faces", "Decimate to about Target Faces faces (at most that many)"),
)

VOX_ITEMS = (
    ("INDEX", "One Model", "Import the model at Model Index"),
    ("ALL", "All Models", "Import every model of the file as its own object"),
)


#: options of the operators' copies of the settings: never remembered from the last call, so a
#: button press always takes the sidebar's current settings (a script's arguments still win)
OPERATOR = {"options": {"SKIP_SAVE"}}


# Shared definitions, so the PropertyGroup and the operators cannot drift apart.
def size_mode_property(**extra):
    # Resolution by default: it adapts to every object (a part modelled in millimetres and a
    # 0.18-unit model both get 64 voxels on their longest side); a voxel size is the user's choice
    return EnumProperty(name="Size", description="How the grid size is chosen",
                        items=SIZE_MODE_ITEMS, default="RESOLUTION", **extra)


def voxel_size_property(**extra):
    return FloatProperty(
        name="Voxel Size",
        description="Voxel edge in world units (object scale included); the grid it gives is "
        f"shown below (at most {RESOLUTION_MAX} voxels along a side)",
        default=VOXEL_SIZE_DEFAULT, min=VOXEL_SIZE_MIN, soft_min=0.001, soft_max=1.0,
        step=1, precision=4, subtype="DISTANCE", unit="LENGTH", **extra)


def resolution_property(**extra):
    return IntProperty(
        name="Resolution",
        description=f"Voxels along the longest side of each object ({RESOLUTION_MIN}-"
        f"{RESOLUTION_MAX}; above 256 runs take minutes)",
        default=RESOLUTION_DEFAULT, min=RESOLUTION_MIN, max=RESOLUTION_MAX,
        soft_min=8, soft_max=256, **extra)


def method_property(items=METHOD_ITEMS, **extra):
    return EnumProperty(name="Method", description="Reconstruction method", items=items,
                        default="agndc", **extra)


def threads_property(**extra):
    return IntProperty(name="Threads", description="CPU threads for the network (0 = Auto)",
                       default=0, min=0, max=256, **extra)


def compare_mc_property(**extra):
    return BoolProperty(name="Compare with MC",
                        description="Also add the marching-cubes mesh of the same grid (<name>_MC) "
                        "beside the result",
                        default=False, **extra)


def normal_filter_property(**extra):
    return BoolProperty(name="Denoise",
                        description="AGNDC and UNDC: smooth out the network's cell-to-cell noise "
                        "while keeping creases, flat faces and the source's dimensions (bilateral "
                        "normal filter); off: the mesh as contoured",
                        default=True, **extra)


def quads_property(**extra):
    return BoolProperty(name="Quads",
                        description="Make quads, as Voxel Remesh does: each planar, convex pair "
                        "of triangles of one dual-contouring quad becomes a quad (nearly all "
                        "faces of boxes and smooth shapes); the rest stays triangles. Marching "
                        "cubes makes triangles only",
                        default=False, **extra)


def low_poly_property(**extra):
    return BoolProperty(name="Low Poly",
                        description="Merge flat regions into a few large triangles, keeping "
                        "sharp edges and a closed mesh (decimation of the result; the Compare "
                        "with MC mesh stays full)",
                        default=False, **extra)


def low_poly_mode_property(**extra):
    return EnumProperty(name="Decimate To", description="What stops the decimation",
                        items=LOW_POLY_ITEMS, default="ERROR", **extra)


def max_error_property(**extra):
    return FloatProperty(name="Max Error (voxels)",
                         description="Largest distance the surface may move, in voxels of the "
                         "grid (0.25: flat and gently curved regions merge, details stay)",
                         default=0.25, min=0.01, max=10.0, soft_max=2.0, step=5, precision=2,
                         **extra)


def target_faces_property(**extra):
    return IntProperty(name="Target Faces",
                       description="Faces of the result (at most this many; exactly flat regions "
                       "merge whatever the target)",
                       default=5000, min=4, soft_max=200_000, **extra)


def smooth_property(**extra):
    return BoolProperty(name="Smooth Shading", description="Shade the new objects smooth",
                        default=False, **extra)


def use_modifiers_property(**extra):
    return BoolProperty(name="Apply Modifiers",
                        description="Remesh the mesh as shown, with its modifiers (off: the base "
                        "mesh without modifiers)",
                        default=True, **extra)


def output_property(**extra):
    return EnumProperty(name="Output", description="Where the result goes", items=OUTPUT_ITEMS,
                        default="BESIDE", **extra)


class AGNDC_RemeshSettings(bpy.types.PropertyGroup):
    size_mode: size_mode_property()
    voxel_size: voxel_size_property()
    resolution: resolution_property()
    method: method_property()
    normal_filter: normal_filter_property()
    low_poly: low_poly_property()
    low_poly_mode: low_poly_mode_property()
    max_error: max_error_property()
    target_faces: target_faces_property()
    use_modifiers: use_modifiers_property()
    output: output_property()
    compare_mc: compare_mc_property()
    quads: quads_property()
    smooth: smooth_property()
    threads: threads_property()
