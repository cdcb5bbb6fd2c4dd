"""The add-on's properties: the scene's Segue settings, an armature's roles, the session token."""

from __future__ import annotations

from typing import Any

import bpy
from bpy.props import FloatProperty, PointerProperty, StringProperty

from .roles import ROLES


def _is_curve(_self: Any, obj: bpy.types.Object) -> bool:
    return bool(obj.type == "CURVE")


def _is_armature(_self: Any, obj: bpy.types.Object) -> bool:
    return bool(obj.type == "ARMATURE")


class SegueSceneSettings(bpy.types.PropertyGroup):
    """Segue's settings of a scene (saved with the .blend; the token is not)."""

    url: StringProperty(name="URL", description="the Segue service", default="http://127.0.0.1:8000")
    database: StringProperty(name="Database", description="the database to generate with (id or name)")
    request: StringProperty(
        name="Request", description="more of the request, JSON (as the HTTP API takes it)", default="{}"
    )
    path: PointerProperty(
        name="Path", type=bpy.types.Object, poll=_is_curve, description="the curve to walk (walk databases)"
    )
    speed: FloatProperty(
        name="Speed", description="walking speed along the path (m/s)", default=1.3, min=0.1, max=6.0
    )
    bpm: FloatProperty(
        name="BPM",
        description="the music's tempo when the scene has no sound strip",
        default=120.0,
        min=0.0,
        max=400.0,
    )
    leader: PointerProperty(
        name="Leader",
        type=bpy.types.Object,
        poll=_is_armature,
        description="the armature whose action leads (Partner databases)",
    )


_ROLE_PROPS = {
    role: StringProperty(name=role, description=f"the bone playing the {role} (Unity/Godot humanoid name)")
    for role in ROLES
}
SegueRoles = type(
    "SegueRoles",
    (bpy.types.PropertyGroup,),
    {
        "__annotations__": dict(_ROLE_PROPS),
        "__doc__": "Which bone plays each part of the body (the Rig panel).",
    },
)

CLASSES = (SegueSceneSettings, SegueRoles)


def register_properties() -> None:
    bpy.types.Scene.segue = PointerProperty(type=SegueSceneSettings)
    bpy.types.Object.segue_roles = PointerProperty(type=SegueRoles)
    bpy.types.WindowManager.segue_token = StringProperty(
        name="Token", description="bearer token (not saved with the file)", subtype="PASSWORD"
    )


def unregister_properties() -> None:
    del bpy.types.WindowManager.segue_token
    del bpy.types.Object.segue_roles
    del bpy.types.Scene.segue
