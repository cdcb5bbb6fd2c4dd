"""A retargeted motion written into the character's own glTF file, so that it binds to the rig.

:func:`bound_glb` takes the user's glTF/GLB character and a motion of its skin's joints (from
:func:`motion.retarget.retarget` on :func:`motion.retarget.character.gltf_character`, root motion
placed by :mod:`motion.retarget.rootmotion`) and returns a GLB that is

* the user's file with one animation added (``animation_only=False``): every node, name,
  hierarchy, skin, mesh, material, texture and earlier animation kept as they were, the new
  animation first among them (Blender makes the first animation the armature's active action
  and stashes the others in NLA tracks; a character that had an idle played it before); or
* only the skeleton (``animation_only=True``): the skin's joints and the nodes above them, with
  their names, rest transforms, hierarchy and the skin's inverse bind matrices, no mesh, and the
  animation: a file that binds to the character by node (bone) names.

Channels target the skin's joint nodes only; nodes above the skin's root (an ``Armature`` node
with a 0.01 scale, say) are never animated. Each joint gets a rotation channel (LINEAR, one key
per frame, one key when it never changes); a joint gets a translation channel when its
translation leaves its rest value (the joints carrying root motion). Values are in each node's
parent space, so a parent's scale (centimetre rigs) is respected: a joint's animated world
transform is the motion's world position and rotation with the joint's rest world scale, and its
local transform is that relative to its parent node's animated world transform (non-joint nodes
inside the skeleton follow their parent). A joint node given as a ``matrix`` is rewritten as
translation, rotation and scale (glTF animates only those).

``events`` (:mod:`motion.export.events`) are written where engines read them: the animation's
``extras``, the scene's ``extras`` and the skin root node's ``extras`` (Blender shows the last two
as custom properties), each as ``{"events": [...]}``.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from .. import rotations as rot
from ..errors import ExportError, MotionError
from ..motion import Motion
from .glb import FLOAT, _Builder, _container, _floats, _label
from .gltf_doc import read_gltf

Array = npt.NDArray[np.float64]

__all__ = ["bound_glb", "skin_joint_nodes"]


def _node_trs(node: dict[str, Any]) -> tuple[Array, Array, Array]:
    """A node's translation ``(3,)``, rotation ``(4,)`` and scale ``(3,)`` (from ``matrix`` too)."""
    if "matrix" in node:
        m = np.array(node["matrix"], dtype=np.float64).reshape(4, 4).T
        scale = np.linalg.norm(m[:3, :3], axis=0)
        r = m[:3, :3] / np.where(scale > 0, scale, 1.0)
        if np.linalg.det(r) < 0:
            scale[0], r[:, 0] = -scale[0], -r[:, 0]
        return m[:3, 3].copy(), rot.from_matrix(r), scale
    return (
        np.array(node.get("translation", [0.0, 0.0, 0.0]), dtype=np.float64),
        rot.normalize(np.array(node.get("rotation", [0.0, 0.0, 0.0, 1.0]), dtype=np.float64)),
        np.array(node.get("scale", [1.0, 1.0, 1.0]), dtype=np.float64),
    )


def _matrix(t: Array, q: Array, s: Array) -> Array:
    m = np.eye(4)
    m[:3, :3] = rot.to_matrix(q) * s
    m[:3, 3] = t
    return m


def _polar(lin: Array) -> Array:
    """The rotation part ``(..., 3, 3)`` of linear maps ``(..., 3, 3)`` (polar decomposition)."""
    u, _, vt = np.linalg.svd(lin)
    return np.asarray(u @ vt)


def skin_joint_nodes(doc: dict[str, Any]) -> dict[str, int]:
    """Joint name -> node index of the document's first skin (names must be unique there)."""
    nodes = doc.get("nodes", [])
    skins = doc.get("skins", [])
    if not skins or not skins[0].get("joints"):
        raise ExportError("the glTF file has no skin with joints: a character needs a skinned skeleton")
    out: dict[str, int] = {}
    for j in skins[0]["joints"]:
        name = str(nodes[int(j)].get("name") or f"joint{int(j)}")
        if name in out:
            raise ExportError(f"the skin's joint names are not unique ({name!r})")
        out[name] = int(j)
    return out


class _Tracks:
    """Per joint node, the local translation ``(F, 3)`` and rotation ``(F, 4)`` of each frame, in
    its parent node's space, and whether the translation leaves its rest value."""

    def __init__(self, doc: dict[str, Any], motion: Motion) -> None:
        nodes = doc["nodes"]
        joints = skin_joint_nodes(doc)
        names = motion.skeleton.names
        missing = [n for n in names if n not in joints]
        extra = [n for n in joints if n not in set(names)]
        if missing or extra:
            raise ExportError(
                "the motion's joints are not the character's skin joints "
                f"(not in the skin: {missing[:5]}; not in the motion: {extra[:5]}): retarget onto this file"
            )
        self.parent = {int(c): i for i, nd in enumerate(nodes) for c in nd.get("children", [])}
        self.local = [_matrix(*_node_trs(nd)) for nd in nodes]
        world: dict[int, Array] = {}

        def rest_world(i: int) -> Array:
            if i not in world:
                p = self.parent.get(i)
                world[i] = self.local[i] if p is None else rest_world(p) @ self.local[i]
            return world[i]

        pos, grot = motion.fk()
        pos = pos * motion.metres_per_unit
        f = motion.num_frames
        anim: dict[int, Array] = {}
        for k, name in enumerate(names):
            n = joints[name]
            lin = rest_world(n)[:3, :3]
            shape = _polar(lin).T @ lin  # the rest world scale, in the joint's own frame
            a = np.tile(np.eye(4), (f, 1, 1))
            a[:, :3, :3] = rot.to_matrix(grot[:, k]) @ shape
            a[:, :3, 3] = pos[:, k]
            anim[n] = a
        joint_set = set(anim)

        def inside(i: int) -> bool:  # a node below a joint moves with it
            p = self.parent.get(i)
            while p is not None and p not in joint_set:
                p = self.parent.get(p)
            return p is not None

        def anim_world(i: int | None) -> Array:
            if i is None:
                return np.eye(4)
            if i in anim:
                return anim[i]
            if inside(i):
                anim[i] = anim_world(self.parent.get(i)) @ self.local[i]
                return anim[i]
            return rest_world(i)

        self.translations: dict[int, Array] = {}
        self.rotations: dict[int, Array] = {}
        self.moves: dict[int, bool] = {}
        for name in names:
            n = joints[name]
            p = self.parent.get(n)
            local = np.linalg.inv(anim_world(p)) @ anim[n]
            t = local[:, :3, 3]
            rest_t, _, _ = _node_trs(nodes[n])
            parent_scale = (
                abs(float(np.linalg.det(rest_world(p)[:3, :3]))) ** (1 / 3) if p is not None else 1.0
            )
            tol = 1e-4 / max(parent_scale, 1e-12)  # 0.1 mm in the parent's units
            self.translations[n] = t
            self.moves[n] = bool(np.any(np.abs(t - rest_t) > tol))
            self.rotations[n] = rot.make_continuous(rot.normalize(rot.from_matrix(_polar(local[:, :3, :3]))))
        self.order = [joints[name] for name in names]
        self.root = joints[names[0]]


def _write_animation(
    b: _Builder, motion: Motion, tracks: _Tracks, node_of: dict[int, int], name: str
) -> dict[str, Any]:
    """The animation (channels on ``node_of[node]``), its data appended to ``b``."""
    f = motion.num_frames
    times = (np.arange(f, dtype=np.float64) / motion.fps).astype(np.float32)
    if f > 1 and not np.all(np.diff(times) > 0):
        raise ExportError(f"frame times at {motion.fps} fps do not increase in float32; resample the motion")
    all_t = b.accessor(b.view(times), 0, FLOAT, f, "SCALAR", times[:1], times[-1:])
    one_t: int | None = None
    channels: list[dict[str, Any]] = []
    samplers: list[dict[str, Any]] = []
    for n in tracks.order:
        for path, values, kind in (
            ("rotation", tracks.rotations[n], "VEC4"),
            ("translation", tracks.translations[n], "VEC3"),
        ):
            if path == "translation" and not tracks.moves[n]:
                continue
            v32 = values.astype(np.float32)
            if f > 1 and np.all(v32 == v32[:1]):
                v32 = v32[:1]
            if len(v32) == 1 and f > 1:
                if one_t is None:
                    zero = np.zeros(1, dtype=np.float32)
                    one_t = b.accessor(b.view(zero), 0, FLOAT, 1, "SCALAR", zero, zero)
                t_acc = one_t
            else:
                t_acc = all_t
            out = b.accessor(b.view(np.ascontiguousarray(v32)), 0, FLOAT, len(v32), kind)
            channels.append({"sampler": len(samplers), "target": {"node": node_of[n], "path": path}})
            samplers.append({"input": t_acc, "interpolation": "LINEAR", "output": out})
    return {"name": name, "channels": channels, "samplers": samplers}


def _unique(name: str, taken: set[str]) -> str:
    out, k = name, 1
    while out in taken:
        k += 1
        out = f"{name}_{k}"
    return out


def bound_glb(
    character: bytes,
    motion: Motion,
    *,
    animation_only: bool = False,
    events: Sequence[dict[str, Any]] | None = None,
    base_dir: str | Path | None = None,
) -> bytes:
    """The motion as an animation of the character's own glTF file (module docstring).

    Parameters
    ----------
    character:
        The character's glTF/GLB file content (its first skin is the rig).
    motion:
        The motion of exactly that skin's joints (named as its nodes), world space, any units
        (converted to metres with ``motion.metres_per_unit``), ``F >= 1`` frames.
    animation_only:
        Write the skeleton and the animation only (binds by node names), not the whole file.
    events:
        Timed events (seconds) written to the animation's, the scene's and the skin root's extras.
    base_dir:
        Folder of a ``.gltf`` character's buffer files.

    Raises
    ------
    ExportError
        When the file is not glTF, has no skin, the motion's joints are not the skin's, or the
        motion cannot be exported (no frames, non-finite values, times not increasing).
    """
    if motion.num_frames == 0:
        raise ExportError(f"cannot export {_label(motion)}: it has no frames")
    if not (np.all(np.isfinite(motion.rotations)) and np.all(np.isfinite(motion.root_positions))):
        raise ExportError(f"cannot export {_label(motion)}: it holds non-finite values (NaN or inf)")
    doc, data = read_gltf(character, base_dir)
    try:
        tracks = _Tracks(doc, motion)
    except (IndexError, KeyError, TypeError, ValueError, RecursionError, MotionError) as exc:
        raise ExportError(f"malformed glTF node hierarchy: {exc}") from None
    evs = None if events is None else list(events)
    if animation_only:
        doc, data, node_of = _skeleton_only(doc, data, tracks)
    else:
        node_of = {n: n for n in tracks.order}
        for n in tracks.order:  # glTF animates TRS only
            node = doc["nodes"][n]
            if "matrix" in node:
                t, q, s = _node_trs(node)
                del node["matrix"]
                node.update(translation=_floats(t), rotation=_floats(q), scale=_floats(s))
    b = _Builder()
    b.data = data
    b.views = doc.setdefault("bufferViews", [])
    b.accessors = doc.setdefault("accessors", [])
    taken = {str(a.get("name", "")) for a in doc.get("animations", [])}
    animation = _write_animation(b, motion, tracks, node_of, _unique(_label(motion), taken))
    if evs is not None:
        animation["extras"] = {"events": evs}
        scene = doc["scenes"][int(doc.get("scene", 0))] if doc.get("scenes") else None
        if scene is not None:
            scene.setdefault("extras", {})["events"] = evs
        doc["nodes"][node_of[tracks.root]].setdefault("extras", {})["events"] = evs
    doc.setdefault("animations", []).insert(0, animation)  # first: the one importers make active
    doc["buffers"] = [{"byteLength": len(b.data)}]
    generator = str(doc.get("asset", {}).get("generator", ""))
    doc.setdefault("asset", {"version": "2.0"})["generator"] = (generator + " + segue").strip(" +")
    return _container(doc, bytes(b.data))


def _skeleton_only(
    doc: dict[str, Any], data: bytearray, tracks: _Tracks
) -> tuple[dict[str, Any], bytearray, dict[int, int]]:
    """A new document of the skin's joints and the nodes above them, with the skin (its inverse
    bind matrices copied) and no mesh; and old node index -> new node index."""
    nodes = doc["nodes"]
    keep: set[int] = set()
    for n in tracks.order:
        i: int | None = n
        while i is not None and i not in keep:
            keep.add(i)
            i = tracks.parent.get(i)
    order = sorted(keep)
    new_of = {old: k for k, old in enumerate(order)}
    new_nodes = []
    for old in order:
        src = nodes[old]
        node = {k: v for k, v in src.items() if k in ("name", "translation", "rotation", "scale", "extras")}
        if "matrix" in src:
            t, q, s = _node_trs(src)
            node.update(translation=_floats(t), rotation=_floats(q), scale=_floats(s))
        kids = [new_of[int(c)] for c in src.get("children", []) if int(c) in keep]
        if kids:
            node["children"] = kids
        new_nodes.append(node)
    b = _Builder()
    skin_src = doc["skins"][0]
    skin: dict[str, Any] = {"joints": [new_of[int(j)] for j in skin_src["joints"]]}
    if "name" in skin_src:
        skin["name"] = skin_src["name"]
    if "skeleton" in skin_src and int(skin_src["skeleton"]) in keep:
        skin["skeleton"] = new_of[int(skin_src["skeleton"])]
    if "inverseBindMatrices" in skin_src:
        acc = doc["accessors"][int(skin_src["inverseBindMatrices"])]
        view = doc["bufferViews"][int(acc["bufferView"])]
        start = int(view.get("byteOffset", 0)) + int(acc.get("byteOffset", 0))
        count = int(acc["count"])
        stride = int(view.get("byteStride", 64))
        raw = np.frombuffer(bytes(data), np.uint8)
        rows = [raw[start + k * stride : start + k * stride + 64] for k in range(count)]
        ibm = np.frombuffer(b"".join(r.tobytes() for r in rows), dtype="<f4").reshape(count, 16)
        skin["inverseBindMatrices"] = b.accessor(b.view(ibm), 0, FLOAT, count, "MAT4")
    roots = [new_of[i] for i in order if tracks.parent.get(i) is None]
    out: dict[str, Any] = {
        "asset": dict(doc.get("asset", {"version": "2.0"})),
        "scene": 0,
        "scenes": [{"name": "skeleton", "nodes": roots}],
        "nodes": new_nodes,
        "skins": [skin],
        "accessors": b.accessors,
        "bufferViews": b.views,
    }
    return out, b.data, new_of
