"""Goals the result misses, marked in the 3D viewport: a red ring at the goal and a line to where
the character's hips were at its frame (met goals: a small green ring)."""

from __future__ import annotations

import math
from typing import Any

import bpy

from .state import SESSION

_HANDLE: Any = None


def _ring(c: tuple[float, float, float], r: float, n: int = 32) -> list[tuple[float, float, float]]:
    pts = [
        (c[0] + r * math.cos(2 * math.pi * k / n), c[1] + r * math.sin(2 * math.pi * k / n), c[2] + 0.005)
        for k in range(n)
    ]
    return [p for k in range(n) for p in (pts[k], pts[(k + 1) % n])]


def _draw() -> None:
    view = SESSION.job
    if view is None or not view.goals:
        return
    import gpu
    from gpu_extras.batch import batch_for_shader

    shader = gpu.shader.from_builtin("UNIFORM_COLOR")
    gpu.state.line_width_set(3.0)
    gpu.state.depth_test_set("NONE")
    for g in view.goals:
        lines = _ring(g.position, 0.3 if not g.satisfied else 0.12)
        if not g.satisfied and g.reached is not None:
            lines += [(g.position[0], g.position[1], 0.01), (g.reached[0], g.reached[1], 0.01)]
        batch = batch_for_shader(shader, "LINES", {"pos": lines})
        shader.uniform_float("color", (0.9, 0.15, 0.1, 1.0) if not g.satisfied else (0.2, 0.8, 0.3, 1.0))
        batch.draw(shader)
    gpu.state.line_width_set(1.0)


def register_drawing() -> None:
    global _HANDLE
    if _HANDLE is None and not bpy.app.background:
        _HANDLE = bpy.types.SpaceView3D.draw_handler_add(_draw, (), "WINDOW", "POST_VIEW")


def unregister_drawing() -> None:
    global _HANDLE
    if _HANDLE is not None:
        bpy.types.SpaceView3D.draw_handler_remove(_HANDLE, "WINDOW")
        _HANDLE = None
