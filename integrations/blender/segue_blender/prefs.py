"""The add-on's preferences: a local Segue service (its ``segue`` executable, data, databases)."""

from __future__ import annotations

import bpy
from bpy.props import StringProperty


class SeguePreferences(bpy.types.AddonPreferences):
    bl_idname = __package__ or "segue_blender"

    segue_executable: StringProperty(
        name="segue executable",
        description="the `segue` program of a venv where Segue is installed (e.g. ~/venvs/segue/bin/segue)",
        subtype="FILE_PATH",
    )
    data_dir: StringProperty(
        name="Data folder",
        description="the local service's data (default: Blender's user data folder)",
        subtype="DIR_PATH",
    )
    import_dirs: StringProperty(
        name="Databases to serve",
        description="folders `segue build` wrote, separated by ';' (segue serve --import DIR)",
    )

    def draw(self, context: bpy.types.Context) -> None:
        layout = self.layout
        layout.prop(self, "segue_executable")
        layout.prop(self, "data_dir")
        layout.prop(self, "import_dirs")
        row = layout.row()
        row.operator("segue.start_local")
        row.operator("segue.stop_local")
        layout.label(text="The local service runs `segue serve` on a free port and stops when Blender exits.")
