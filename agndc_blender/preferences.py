"""Add-on preferences (Edit > Preferences > Add-ons > AGNDC Remesher), keyed by ``__package__``
so the same code works as an extension (``bl_ext.<repo>.agndc_remesher``) and as a legacy add-on."""

import bpy
from bpy.props import IntProperty, StringProperty


class AGNDC_AddonPreferences(bpy.types.AddonPreferences):
    bl_idname = __package__

    checkpoint: StringProperty(
        name="Checkpoint",
        description="Custom AGNDC weights (.safetensors); empty uses the weights shipped with "
        "the extension",
        subtype="FILE_PATH",
        default="",
    )
    default_threads: IntProperty(
        name="Default Threads",
        description="CPU threads for the network when the panel says 0 (Auto); 0 leaves one "
        "core free for the interface",
        default=0,
        min=0,
        max=256,
    )

    def draw(self, context):
        layout = self.layout
        layout.prop(self, "checkpoint")
        layout.prop(self, "default_threads")


def get(context=None):
    """This add-on's preferences, or None when the add-on is not enabled (batch use)."""
    context = context or bpy.context
    addon = context.preferences.addons.get(__package__)
    return addon.preferences if addon is not None else None
