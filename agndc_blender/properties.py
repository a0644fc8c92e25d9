"""Settings shared by the sidebar, the Object Data > Remesh button and the operators: one
PropertyGroup behind ``Scene.agndc``. Operator properties of the same names override them."""

import bpy
from bpy.props import BoolProperty, EnumProperty, IntProperty

#: resolution limits: the operator validates these (with a clear message) instead of clamping
RESOLUTION_MIN, RESOLUTION_DEFAULT, RESOLUTION_MAX = 8, 64, 256

METHOD_ITEMS = (
    ("agndc", "AGNDC", "Attention-guided multi-scale neural dual contouring (shipped weights)"),
    ("undc", "UNDC", "Single-scale neural dual contouring baseline (needs its weights)"),
    ("mc", "Marching Cubes", "Marching cubes of the same grid (no network)"),
)

# Shared definitions, so the PropertyGroup and the operators cannot drift apart.
def resolution_property():
    return IntProperty(
        name="Resolution",
        description=f"Voxels along the longest side of each object's bounding box "
        f"({RESOLUTION_MIN}-{RESOLUTION_MAX})",
        default=RESOLUTION_DEFAULT,
        soft_min=RESOLUTION_MIN,
        soft_max=RESOLUTION_MAX,
    )


def method_property():
    return EnumProperty(name="Model", description="Reconstruction method", items=METHOD_ITEMS,
                        default="agndc")


def threads_property():
    return IntProperty(name="Threads", description="CPU threads for the network (0 = Auto)",
                       default=0, min=0, max=256)


def compare_mc_property():
    return BoolProperty(name="Compare with MC",
                        description="Also add the marching-cubes mesh of the same grid (<name>_MC)",
                        default=True)


def smooth_property():
    return BoolProperty(name="Smooth Shading", description="Shade the new objects smooth",
                        default=False)


class AGNDC_RemeshSettings(bpy.types.PropertyGroup):
    resolution: resolution_property()
    method: method_property()
    threads: threads_property()
    compare_mc: compare_mc_property()
    smooth: smooth_property()
