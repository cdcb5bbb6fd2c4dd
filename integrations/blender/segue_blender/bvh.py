"""An armature's action as a Segue clip: the GLB Blender's glTF exporter writes of it (axes
converted to Y up, constraints, drivers and NLA evaluated, one key per frame), turned into BVH
text (Segue's clip format) in plain Python.

Each skin joint becomes a BVH joint (its parent the nearest joint above it), named as the GLB
names it (the add-on renames role bones first: :func:`.roles.upload_names`), offsets from the rest
pose in metres, the root with position channels; rotations are each joint's turn since its rest
pose relative to its parent's (BVH joints rest unrotated), as intrinsic ZXY Euler angles in
degrees (``Zrotation Xrotation Yrotation``). Leaf joints get an End Site at their bone's tip.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

from . import gltf, mat4
from .mat4 import Vec3

ORDER = "ZXY"


def _rot3(m: mat4.Mat4) -> tuple[float, ...]:
    return mat4.matrix3_of_quat(mat4.rotation_of(m))


def _mul3(a: Sequence[float], b: Sequence[float]) -> tuple[float, ...]:
    return tuple(sum(a[3 * r + k] * b[3 * k + c] for k in range(3)) for r in range(3) for c in range(3))


def _t3(a: Sequence[float]) -> tuple[float, ...]:
    return (a[0], a[3], a[6], a[1], a[4], a[7], a[2], a[5], a[8])


def glb_to_bvh(
    raw: bytes, fps: float, tips: Mapping[str, Vec3] | None = None, origin: tuple[float, float] = (0.0, 0.0)
) -> str:
    """BVH text of a GLB's skin (the first) and its last animation, sampled at ``fps`` from the
    animation's first key to its last (module docstring).

    Parameters
    ----------
    raw:
        The GLB (one armature, one animation; glTF axes, metres).
    fps:
        The BVH's frame rate (the scene's).
    tips:
        Joint name -> its bone's tip in glTF world axes at rest, for End Sites (default: a tenth
        of the parent bone along it).
    origin:
        A floor point ``[x, z]`` (glTF axes) that becomes the clip's origin (its root positions
        are moved by minus it).
    """
    if not (math.isfinite(fps) and fps > 0):
        raise ValueError(f"fps must be positive, not {fps!r}")
    doc, binary = gltf.split_glb(raw)
    nodes = gltf.nodes_of(doc)
    joints = gltf.skin_joints(doc)
    anim = gltf.animation(doc, binary)
    in_skin = set(joints)

    def joint_parent(n: int) -> int | None:
        p = nodes[n].parent
        while p is not None and p not in in_skin:
            p = nodes[p].parent
        return p

    jparent = {n: joint_parent(n) for n in joints}
    roots = [n for n in joints if jparent[n] is None]
    if len(roots) != 1:
        raise gltf.GltfError(f"the skin has {len(roots)} root joints; a clip needs one tree")
    kids: dict[int, list[int]] = {n: [] for n in joints}
    for n in joints:
        p = jparent[n]
        if p is not None:
            kids[p].append(n)
    order: list[int] = []
    stack = [roots[0]]
    while stack:
        n = stack.pop()
        order.append(n)
        stack.extend(reversed(kids[n]))
    rest = gltf.rest_world(nodes)
    rest_pos = {n: mat4.translation(rest[n]) for n in joints}
    rest_rot = {n: _rot3(rest[n]) for n in joints}
    # the nodes to evaluate each frame: the joints and everything above them
    needed: list[int] = []
    seen: set[int] = set()

    def add(i: int) -> None:
        p = nodes[i].parent
        if p is not None and p not in seen:
            add(p)
        if i not in seen:
            seen.add(i)
            needed.append(i)

    for n in joints:
        add(n)
    t0 = anim.times[0] if anim.times else 0.0
    t1 = anim.times[-1] if anim.times else 0.0
    count = max(1, int(math.floor((t1 - t0) * fps + 1e-3)) + 1)  # float32 key times
    lines = ["HIERARCHY"]

    def offset(n: int) -> Vec3:
        p = jparent[n]
        a, b = rest_pos[n], (rest_pos[p] if p is not None else (0.0, 0.0, 0.0))
        return (a[0] - b[0], a[1] - b[1], a[2] - b[2])

    def write(n: int, depth: int) -> None:
        pad = "\t" * depth
        lines.append(f"{pad}{'ROOT' if depth == 0 else 'JOINT'} {nodes[n].name}")
        lines.append(f"{pad}{{")
        o = offset(n)
        lines.append(f"{pad}\tOFFSET {o[0]:.6f} {o[1]:.6f} {o[2]:.6f}")
        chans = "Zrotation Xrotation Yrotation"
        if depth == 0:
            lines.append(f"{pad}\tCHANNELS 6 Xposition Yposition Zposition {chans}")
        else:
            lines.append(f"{pad}\tCHANNELS 3 {chans}")
        for c in kids[n]:
            write(c, depth + 1)
        if not kids[n]:
            tip = (tips or {}).get(nodes[n].name)
            e: tuple[float, ...]
            if tip is not None:
                e = (tip[0] - rest_pos[n][0], tip[1] - rest_pos[n][1], tip[2] - rest_pos[n][2])
            else:
                e = tuple(0.1 * v for v in o) if any(o) else (0.0, 0.05, 0.0)
            lines.append(f"{pad}\tEnd Site")
            lines.append(f"{pad}\t{{")
            lines.append(f"{pad}\t\tOFFSET {e[0]:.6f} {e[1]:.6f} {e[2]:.6f}")
            lines.append(f"{pad}\t}}")
        lines.append(f"{pad}}}")

    write(roots[0], 0)
    lines += ["MOTION", f"Frames: {count}", f"Frame Time: {1.0 / fps:.8f}"]
    for k in range(count):
        t = t0 + k / fps
        world: dict[int, mat4.Mat4] = {}
        for i in needed:
            nd = nodes[i]
            ch = anim.channels.get(i)
            if ch:
                local = mat4.from_trs(
                    ch["translation"].at(t) if "translation" in ch else nd.translation,
                    ch["rotation"].at(t, rotation=True) if "rotation" in ch else nd.rotation,
                    ch["scale"].at(t) if "scale" in ch else nd.scale,
                )
            else:
                local = nd.matrix()
            p = nd.parent
            world[i] = local if p is None else mat4.mul(world[p], local)
        turn = {n: _mul3(_rot3(world[n]), _t3(rest_rot[n])) for n in joints}
        values: list[float] = []
        for n in order:
            p = jparent[n]
            local3 = turn[n] if p is None else _mul3(_t3(turn[p]), turn[n])
            if p is None:
                x, y, z = mat4.translation(world[n])
                values += [x - origin[0], y, z - origin[1]]
            values += [math.degrees(a) for a in mat4.euler_from_matrix3(local3, ORDER)]
        lines.append(" ".join(f"{v:.6f}" for v in values))
    return "\n".join(lines) + "\n"
