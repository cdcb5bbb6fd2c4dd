"""Segue inside Blender: author constraints in the scene, generate motion by example with a Segue
service, and see each better solution on your own character as it arrives.

A thin client of Segue's HTTP API with Blender's bundled Python only (``http.client``, ``json``,
``struct``, ``threading``, ``bpy``, ``mathutils``); it never imports Segue. The plain modules
(:mod:`.client`, :mod:`.gltf`, :mod:`.binding`, :mod:`.authoring`, :mod:`.roles`, :mod:`.axes`,
:mod:`.bvh`, :mod:`.jobs`, :mod:`.local_service`) import no ``bpy`` at their top, so they are
tested outside Blender too; ``bpy`` is imported when Blender registers the add-on.

Installs as an extension (``blender_manifest.toml``, Blender 4.2+) or as a legacy add-on
(``bl_info``): ``segue blender-addon --out segue_blender.zip`` writes the zip. See docs/blender.md.
"""

from __future__ import annotations

bl_info = {
    "name": "Segue",
    "author": "Segue contributors",
    "version": (0, 1, 0),
    "blender": (4, 2, 0),
    "location": "3D Viewport > Sidebar > Segue",
    "description": "Motion synthesis by example on your own character, streamed as it improves",
    "category": "Animation",
}

_REGISTERED: list[type] = []


def register() -> None:
    import bpy

    from . import draw, ops, prefs, props, ui

    for cls in (*props.CLASSES, prefs.SeguePreferences, *ops.CLASSES, *ui.CLASSES):
        bpy.utils.register_class(cls)
        _REGISTERED.append(cls)
    props.register_properties()
    draw.register_drawing()


def unregister() -> None:
    import bpy

    from . import draw, local_service, ops, props

    draw.unregister_drawing()
    for job in list(ops.JOBS.values()):
        job.runner.abandon()
    ops.JOBS.clear()
    if bpy.app.timers.is_registered(ops._timer):
        bpy.app.timers.unregister(ops._timer)
    local_service.stop_all()
    props.unregister_properties()
    while _REGISTERED:
        bpy.utils.unregister_class(_REGISTERED.pop())
