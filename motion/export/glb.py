"""Export a :class:`~motion.motion.Motion` as a binary glTF 2.0 file (GLB).

The file holds one scene with a skinned skeleton and one animation, in glTF's convention, which is
also Segue's internal one: right-handed, Y up, metres, quaternions ``(x, y, z, w)``. Lengths are
converted with :attr:`Motion.metres_per_unit <motion.motion.Motion.metres_per_unit>` (a motion of
unknown units is written as if its unit were the metre).

Layout
------
GLB container
    12-byte header (``b"glTF"``, version 2, total length), a JSON chunk padded with spaces and a BIN
    chunk padded with zeros, both to 4 bytes. Every buffer view starts on a 4-byte boundary, and
    every accessor's ``byteOffset`` is a multiple of 4.
Nodes
    ``0 .. J-1``: one node per joint, in skeleton order (node index = joint index), named after the
    joint, with ``children`` following ``skeleton.parents`` and its rest transform (below). Then
    one leaf node per End Site, named ``"<parent>_end"`` (``"<parent>_end_<k>"`` for further End
    Sites of the same joint), child of its joint but not a joint of the skin. Last, when a mesh is
    written, the mesh node (``mesh``, ``skin``, no transform), a root of the scene beside the
    skeleton root.
Rest (bind) pose
    The pose engines and retargeting tools read (Humanoid/T-pose set-up): it stands on the floor.
    Every joint's rest translation is its offset, except the body root (the hips, under the ground
    root), which stands over the origin at the height that puts the lowest joint or End Site of
    the rest pose at y = 0. Rest rotations are the identity (the skeleton's zero pose) when in
    that pose the legs point down (within 30 degrees of vertical; the left thigh by name,
    :func:`motion.ground.facing_pairs`, to the farthest point below it). Skeletons whose zero pose
    lies down (Bandai-Namco files) take instead the local rotations of the first frame in which
    the legs point down (the hips' heading removed), written as node ``rotation``. Inverse bind
    matrices and the bone mesh follow this pose; the animation channels override it, so the
    animated pose does not depend on it.
Ground root
    With ``ground_root=True`` the motion first gets an explicit ground root joint named
    ``"ground"`` by :func:`motion.ground.add_ground_root` (floor projection of the hips, rotated by
    the heading), so engines and game tools can take root motion. A motion whose root is already
    named ``"ground"`` (e.g. an engine's output) is exported as it is. With ``in_place=True`` a
    static joint named ``"origin"`` at the origin becomes the skin's root, with two children: the
    ground joint, whose track still holds the root motion (floor path and heading) for an
    engine's root-motion setting, and the hips, animated relative to the ground frame. Played as
    is, the body dances over the origin facing +Z; the skeleton keeps a single root.
Several characters
    A combined motion (a crowd or a couple: a static ``world`` root and ``cN_``-prefixed
    characters, :func:`motion.export.characters.split_characters`) is written as one skin per
    character: its own ``cN_ground`` root, joints, bind matrices and mesh node, the rig under its
    own plain (non-joint) node named ``cN`` (so that importers make one armature or Skeleton per
    character: Blender and Godot merge rigs that share a parent), and its own animation named
    ``<motion>_cN``. Characters with the same bind pose share one bone mesh and one bind-matrix
    accessor, so the file grows by the animation of each character only (``bench/glb_size.py``).
Animation
    One animation named after the motion (``"motion"`` when unnamed; one per character, above).
    Key times ``frame / fps``
    seconds in one shared input accessor; LINEAR samplers. Every joint gets a rotation channel
    (local quaternions, signs made continuous over time so that interpolation takes the short
    arc); the root and every joint of ``skeleton.translated_joints`` get a translation channel
    (metres). A channel whose float32 values never change (fingers held still) has one key at
    0 s, which glTF holds for the whole animation.
Events
    ``events`` (foot contacts, beats, labels: :mod:`motion.export.events`) go, as
    ``{"events": [...]}``, in the animation's ``extras`` (a character's animation gets its own
    contacts and the shared beats and labels), in the scene's ``extras`` (all of them) and in each
    character's top node's ``extras`` (its skin root, or its ``cN`` node): Blender keeps scene and
    node extras as custom properties, and Godot's importer drops extras, so a Godot script reads
    them from the file (docs/game-engines.md).
Skin
    ``joints`` = the ``J`` joint nodes (skin joint index = joint index), ``skeleton`` = node 0, and
    ``inverseBindMatrices`` (``MAT4``, column-major) = the inverse of each joint's global rest
    transform.
Mesh (``mesh=True``)
    One primitive drawing every bone of the rest pose as a flat-shaded octahedron from the parent
    joint to the child joint (or End Site), its widest section a fifth of the way along, rigidly
    bound (weight 1) to the parent joint. Width: 3 % of the body size (the largest extent of the
    rest-pose bounding box, which is the standing height for an upright or T-pose rest and still
    the body length for a rest pose lying down), at most a quarter of the bone length, so that
    fingers stay slender. Zero-length bones and the link from the ground root to the hips are not
    drawn. Attributes: ``POSITION``, ``NORMAL`` (``FLOAT VEC3``), ``JOINTS_0`` (``UNSIGNED_SHORT
    VEC4``), ``WEIGHTS_0`` (``FLOAT VEC4``) and indices (``UNSIGNED_SHORT``, or ``UNSIGNED_INT``
    past 65,535 vertices), with one plain grey material.

Example
-------
>>> import motion
>>> from motion.export.glb import glb_bytes
>>> from motion.samples import sample_path
>>> clip = motion.read_bvh(sample_path("walk")).slice(0, 10)
>>> glb_bytes(clip)[:4]
b'glTF'
"""

from __future__ import annotations

import json
import struct
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from .. import rotations as rot
from ..errors import ExportError, MotionError
from ..ground import GROUND_ROOT_NAME, add_ground_root, facing_pairs
from ..motion import Motion
from ..skeleton import Skeleton
from .body import SkinnedMesh, body_mesh
from .characters import split_characters, without_prefix

Array = npt.NDArray[np.float64]
MeshKind = Literal["bones", "body"]

__all__ = ["glb_bytes", "write_glb"]

GLB_MAGIC = b"glTF"
GLB_VERSION = 2
CHUNK_JSON = 0x4E4F534A  # "JSON"
CHUNK_BIN = 0x004E4942  # "BIN\0"

# accessor component types and buffer view targets (glTF 2.0, section 5.1 / 5.11)
UNSIGNED_SHORT = 5123
UNSIGNED_INT = 5125
FLOAT = 5126
ARRAY_BUFFER = 34962
ELEMENT_ARRAY_BUFFER = 34963

BONE_WIDTH_OF_BODY = 0.03  # octahedron width as a fraction of the body size
BONE_WIDTH_OF_LENGTH = 0.25  # ... and at most this fraction of the bone's length
BONE_WAIST = 0.2  # position of the widest section along the bone, from the parent
BONE_COLOUR = (0.72, 0.74, 0.78, 1.0)
BODY_COLOUR = (0.78, 0.71, 0.64, 1.0)  # a mannequin's light wood
_MIN_BONE_OF_BODY = 1e-6  # bones shorter than this fraction of the body size are not drawn
_MAX_SKIN_JOINTS = 65536  # JOINTS_0 is UNSIGNED_SHORT


def glb_bytes(
    motion: Motion,
    *,
    ground_root: bool = True,
    mesh: bool | MeshKind = True,
    in_place: bool = False,
    events: Sequence[dict[str, Any]] | None = None,
    animation: bool = True,
    names: Sequence[str] | None = None,
) -> bytes:
    """The motion as a binary glTF 2.0 file (see the module docstring for the layout).

    Parameters
    ----------
    motion:
        The motion to export, ``F >= 1`` frames, lengths in ``motion.units`` (converted to
        metres with ``motion.metres_per_unit``; unknown units count as metres). A combined
        motion of several characters (:func:`motion.export.characters.split_characters`) gets
        one skin per character.
    ground_root:
        Add an explicit ground root joint named ``"ground"`` with
        :func:`motion.ground.add_ground_root` (skipped when the root already has that name).
    mesh:
        Add a skinned mesh so that any viewer shows the character: ``True`` or ``"bones"`` the
        bone octahedra, ``"body"`` Segue's mannequin (:mod:`motion.export.mannequin`: a body
        with smooth weights and soles on the floor), ``False`` none.
    in_place:
        Keep the body over the origin: the ground joint still carries the root motion (floor
        path and heading) but is not the parent of the hips, whose animation is relative to it
        (needs ``ground_root``).
    events:
        JSON objects (:mod:`motion.export.events`) written to the animations', the scene's and
        the characters' top nodes' ``extras`` as ``{"events": [...]}`` (module docstring).
    animation:
        Write the animation; without it the file is a character (its skin in the bind pose).
    names:
        The joint names to write, one per joint of ``motion`` (default: its own), so that a body
        found under one naming convention can be written under another (a single character,
        without ``ground_root``).

    Returns
    -------
    The GLB file content: right-handed, Y up, metres, key times in seconds.

    Raises
    ------
    ExportError
        When the motion has no frames, holds non-finite values or zero quaternions, has too many
        joints for ``JOINTS_0`` (65,536), its frame times do not increase in float32,
        ``ground_root`` is asked for while a non-root joint is already called ``"ground"``, or
        ``in_place`` is asked for without ``ground_root``.
    """
    if in_place and not ground_root:
        raise ExportError("in-place export needs the ground root (it keeps the root motion)")
    if mesh not in (True, False, "bones", "body"):
        raise ExportError(f"unknown mesh {mesh!r}: bones, body or none")
    if names is not None and (len(names) != motion.num_joints or ground_root):
        raise ExportError("names: one per joint of the motion, and only without a ground root")
    _prepared(motion, False)  # validate the input before splitting it
    split = split_characters(motion)
    chars = [motion] if split is None else split
    plain = [(c, "") if split is None else without_prefix(c) for c in chars]  # names read by name-finders
    prepared = [(_prepared(c, ground_root), pre) for c, pre in plain]
    if in_place:
        prepared = [(_in_place(m), pre) for m, pre in prepared]
    lead = (2 if in_place else 1) if ground_root else 0  # joints before the body root
    b = _Builder()
    times = _Times(b, prepared[0][0]) if animation else None
    nodes: list[dict[str, Any]] = []
    skins: list[dict[str, Any]] = []
    animations: list[dict[str, Any]] = []
    scene_roots: list[int] = []
    meshes: list[dict[str, Any]] = []
    mesh_nodes: list[dict[str, Any]] = []
    shared: list[tuple[_Rest, npt.NDArray[np.intp], int, int | None]] = []  # rest, parents, IBM, mesh
    for m, pre in prepared:
        base = len(nodes)
        rest = _rest_pose(m, lead)
        nodes += _joint_nodes(m, rest, base, pre)
        if names is not None:
            for j, name in enumerate(names):
                nodes[base + j]["name"] = name
        scene_roots.append(base)
        channels: list[dict[str, Any]] = []
        samplers: list[dict[str, Any]] = []
        if times is not None:
            _animation(b, m, times, base, channels, samplers)
            animations.append(
                {
                    "name": _label(motion) if split is None else _label(m),
                    "channels": channels,
                    "samplers": samplers,
                }
            )
        found = next((s for s in shared if _same_rest(s[0], s[1], rest, m.skeleton.parents)), None)
        if found is None:
            ibm = _ibm(b, rest)
            geometry = _skin_mesh(m.skeleton, rest, lead, mesh)
            mesh_index = None
            if geometry is not None:
                mesh_index = len(meshes)
                kind = "body" if mesh == "body" else "bones"
                meshes.append(
                    {"name": m.skeleton.names[0] + "_" + kind, "primitives": [_primitive(b, geometry)]}
                )
            shared.append((rest, m.skeleton.parents, ibm, mesh_index))
        else:
            ibm, mesh_index = found[2], found[3]
        skin: dict[str, Any] = {
            "name": pre + m.skeleton.names[0] + "_skin",
            "joints": list(range(base, base + m.num_joints)),
            "inverseBindMatrices": ibm,
            "skeleton": base,
        }
        if mesh_index is not None:
            mesh_nodes.append(
                {"name": pre + m.skeleton.names[0] + "_mesh", "mesh": mesh_index, "skin": len(skins)}
            )
        skins.append(skin)
    if split is not None:  # each character's rig under its own plain node: one armature each
        for k, (_, pre) in enumerate(prepared):
            nodes.append({"name": pre.rstrip("_") or f"character{k}", "children": [scene_roots[k]]})
            scene_roots[k] = len(nodes) - 1
    scene_roots += range(len(nodes), len(nodes) + len(mesh_nodes))
    nodes += mesh_nodes
    scene: dict[str, Any] = {"name": _label(motion), "nodes": scene_roots}
    if events is not None:
        evs = list(events)
        scene["extras"] = {"events": evs}
        for k, (_, pre) in enumerate(prepared):
            who = pre.rstrip("_")
            mine = [e for e in evs if "character" not in e or e["character"] == who] if split else evs
            if animations:
                animations[k]["extras"] = {"events": mine}
            nodes[scene_roots[k]].setdefault("extras", {})["events"] = mine
    gltf: dict[str, Any] = {
        "asset": {"version": "2.0", "generator": "segue"},
        "scene": 0,
        "scenes": [scene],
        "nodes": nodes,
        "skins": skins,
    }
    if animations:
        gltf["animations"] = animations
    if meshes:
        gltf["meshes"] = meshes
        body = mesh == "body"
        gltf["materials"] = [
            {
                "name": "body" if body else "bone",
                "pbrMetallicRoughness": {
                    "baseColorFactor": list(BODY_COLOUR if body else BONE_COLOUR),
                    "metallicFactor": 0.0,
                    "roughnessFactor": 0.75 if body else 0.7,
                },
            }
        ]
    gltf["accessors"] = b.accessors
    gltf["bufferViews"] = b.views
    gltf["buffers"] = [{"byteLength": len(b.data)}]
    return _container(gltf, bytes(b.data))


@dataclass(frozen=True, slots=True)
class _Rest:
    """The rest (bind) pose of one skin: ``rotations (J, 4)`` and ``translations (J, 3)`` local
    (metres), ``globals (J, 4, 4)`` joint matrices and ``ends (E, 3)`` End Site positions (m)."""

    rotations: Array
    translations: Array
    globals: Array
    ends: Array


def _rest_pose(m: Motion, lead: int) -> _Rest:
    """The rest pose standing on the floor (module docstring, *Rest pose*); joints ``0 .. lead-1``
    are the ground root (and the in-place origin), ``lead`` the body root."""
    sk = m.skeleton
    scale = m.metres_per_unit
    body = lead
    q = rot.identity((sk.num_joints,))
    t = sk.offsets * scale
    t[body] = 0.0
    ends_off = sk.end_site_offsets * scale
    g, ends = _rest_fk(sk.parents, t, q, sk.end_site_parents, ends_off)
    leg = _leg(sk, np.concatenate((g[:, :3, 3], ends)))
    if leg is not None and not _down(np.concatenate((g[:, :3, 3], ends))[None], leg)[0]:
        pos, grot = m.fk()
        pts = np.concatenate((pos, m.end_site_positions(pos, grot)), axis=1)
        down = _down(pts, leg)
        f = int(np.argmax(down)) if down.any() else 0
        q = np.array(m.rotations[f], dtype=np.float64, copy=True)
        if lead:
            q[:lead] = rot.identity()
        else:
            q[0] = rot.multiply(rot.from_yaw(-rot.yaw(q[0])), q[0])
        g, ends = _rest_fk(sk.parents, t, q, sk.end_site_parents, ends_off)
    lowest = min(float(g[lead:, 1, 3].min()), float(ends[:, 1].min()) if ends.size else np.inf)
    t[body] = [0.0, -lowest, 0.0]
    g, ends = _rest_fk(sk.parents, t, q, sk.end_site_parents, ends_off)
    return _Rest(q, t, g, ends)


def _in_place(m: Motion) -> Motion:
    """A grounded motion (joint 0 the ground root, joint 1 the hips) in place: a static origin
    joint at the top, with the ground root and the hips as its two children. The ground root keeps
    the root motion; the hips keep their motion relative to it, so the body stays over the origin
    facing +Z."""
    sk = m.skeleton
    f = m.num_frames
    name = "origin" if "origin" not in sk.names else f"{sk.names[0]}_origin"
    parents = np.concatenate(([-1], sk.parents + 1))
    parents[2] = 0  # the hips hang from the origin, not from the ground root
    pos = ("Xposition", "Yposition", "Zposition")
    channels = ((*pos, "Zrotation", "Yrotation", "Xrotation"), *sk.channels)
    new = Skeleton(
        (name, *sk.names),
        parents,
        np.concatenate((np.zeros((1, 3)), sk.offsets)),
        channels,
        sk.end_site_parents + 1,
        sk.end_site_offsets,
    )
    jt = np.concatenate((m.root_positions[:, None], m.joint_translations), axis=1)
    q = np.concatenate((np.tile(rot.identity(), (f, 1, 1)), m.rotations), axis=1)
    return Motion(new, np.zeros((f, 3)), q, m.fps, joint_translations=jt, units=m.units, name=m.name)


def _rest_fk(
    parents: npt.NDArray[np.intp], t: Array, q: Array, end_parents: npt.NDArray[np.intp], end_off: Array
) -> tuple[Array, Array]:
    """Global ``(J, 4, 4)`` matrices of local translations ``t (J, 3)`` and rotations ``q (J, 4)``,
    and the ``(E, 3)`` End Site positions."""
    local = np.broadcast_to(np.eye(4), (len(parents), 4, 4)).copy()
    local[:, :3, :3] = rot.to_matrix(q)
    local[:, :3, 3] = t
    g = local.copy()
    for j in range(1, len(parents)):
        g[j] = g[parents[j]] @ local[j]
    ends = np.einsum("eab,eb->ea", g[end_parents, :3, :3], end_off) + g[end_parents, :3, 3]
    return g, ends.reshape(-1, 3)


def _leg(sk: Skeleton, points: Array) -> tuple[int, int] | None:
    """``(thigh, tip)``: the left thigh (:func:`motion.ground.facing_pairs`) and the point (joint,
    or End Site numbered from ``J``) of its subtree farthest from it in ``points (J + E, 3)``;
    ``None`` without left/right hips."""
    pairs = facing_pairs(sk)
    if not pairs:
        return None
    thigh = pairs[0][0]
    inside = np.zeros(sk.num_joints, dtype=bool)
    inside[thigh] = True
    for j in range(thigh + 1, sk.num_joints):
        inside[j] = inside[sk.parents[j]] if sk.parents[j] >= 0 else False
    cand = np.concatenate(
        (np.flatnonzero(inside), sk.num_joints + np.flatnonzero(inside[sk.end_site_parents]))
    )
    tip = int(cand[np.argmax(np.linalg.norm(points[cand] - points[thigh], axis=-1))])
    return (thigh, tip) if tip != thigh else None


def _down(points: Array, leg: tuple[int, int]) -> npt.NDArray[np.bool_]:
    """``(F,)`` whether the leg points down (more vertical than 60° from the floor) in
    ``points (F, P, 3)``."""
    v = points[:, leg[1]] - points[:, leg[0]]
    return np.asarray(v[:, 1] < -np.sin(np.radians(60.0)) * np.linalg.norm(v, axis=-1))


def _same_rest(a: _Rest, pa: npt.NDArray[np.intp], b: _Rest, pb: npt.NDArray[np.intp]) -> bool:
    """Whether two skins share their bind pose (then their bind matrices and bone mesh too)."""
    return (
        a.globals.shape == b.globals.shape
        and a.ends.shape == b.ends.shape
        and np.array_equal(pa, pb)
        and np.allclose(a.globals, b.globals, atol=1e-7)
        and np.allclose(a.ends, b.ends, atol=1e-7)
    )


def _joint_nodes(m: Motion, rest: _Rest, base: int, prefix: str = "") -> list[dict[str, Any]]:
    """Nodes ``base .. base+J-1`` (the joints, at their rest translations and rotations, named
    ``prefix + name``) then one leaf per End Site, with ``children`` after ``skeleton.parents``."""
    sk = m.skeleton
    n_joints = sk.num_joints
    nodes: list[dict[str, Any]] = []
    turned = np.any(np.abs(rest.rotations - [0.0, 0.0, 0.0, 1.0]) > 1e-12, axis=1)
    for j, name in enumerate(sk.names):
        node: dict[str, Any] = {"name": prefix + name, "translation": _floats(rest.translations[j])}
        if turned[j]:
            node["rotation"] = _floats(rot.normalize(rest.rotations[j]))
        nodes.append(node)
    children: list[list[int]] = [[] for _ in range(n_joints)]
    for j in range(1, n_joints):
        children[int(sk.parents[j])].append(base + j)
    end_count = [0] * n_joints
    for parent, off in zip(sk.end_site_parents, sk.end_site_offsets * m.metres_per_unit, strict=True):
        p = int(parent)
        suffix = "_end" if end_count[p] == 0 else f"_end_{end_count[p]}"
        end_count[p] += 1
        children[p].append(base + len(nodes))
        nodes.append({"name": prefix + sk.names[p] + suffix, "translation": _floats(off)})
    for j in range(n_joints):
        if children[j]:
            nodes[j]["children"] = children[j]
    return nodes


def _times(b: _Builder, m: Motion) -> int:
    """The shared key-time accessor: ``frame / fps`` seconds (float32, increasing)."""
    n_frames = m.num_frames
    times = (np.arange(n_frames, dtype=np.float64) / m.fps).astype(np.float32)
    if n_frames > 1 and not np.all(np.diff(times) > 0):
        raise ExportError(
            f"frame times at {m.fps} fps do not increase in float32 over {n_frames} frames; "
            "resample the motion before exporting it to glTF"
        )
    return b.accessor(b.view(times), 0, FLOAT, n_frames, "SCALAR", times[:1], times[-1:])


class _Times:
    """The key-time accessors shared by every sampler: all frames, and (made on first use) one key
    at 0 s for channels whose value never changes."""

    def __init__(self, b: _Builder, m: Motion) -> None:
        self.builder = b
        self.frames = _times(b, m)
        self.count = m.num_frames
        self._one: int | None = None

    @property
    def one(self) -> int:
        if self._one is None:
            zero = np.zeros(1, dtype=np.float32)
            self._one = self.builder.accessor(self.builder.view(zero), 0, FLOAT, 1, "SCALAR", zero, zero)
        return self._one


def _animation(
    b: _Builder,
    m: Motion,
    times: _Times,
    base: int,
    channels: list[dict[str, Any]],
    samplers: list[dict[str, Any]],
) -> None:
    """Append the channels and samplers of one skin (joint nodes from ``base``): every joint's
    local quaternions (continuous signs) and the translations of the root and translated joints
    (metres), keyed by the shared times; a channel whose float32 values never change gets a single
    key (``times.one``), which glTF holds for the whole animation."""
    sk = m.skeleton
    n_joints = sk.num_joints
    try:
        quats = rot.make_continuous(rot.normalize(m.rotations), axis=0)
    except MotionError as exc:
        raise ExportError(f"cannot export {_label(m)}: {exc}") from None
    q32 = np.ascontiguousarray(np.swapaxes(quats, 0, 1)).astype(np.float32)  # (J, F, 4)
    moved = np.concatenate(([0], sk.translated_joints)).astype(np.intp)
    trans = np.concatenate((m.root_positions[:, None], m.joint_translations), axis=1) * m.metres_per_unit
    t32 = np.ascontiguousarray(np.swapaxes(trans, 0, 1)).astype(np.float32)  # (1+K, F, 3)
    for nodes, values, path, kind in (
        (np.arange(n_joints), q32, "rotation", "VEC4"),
        (moved, t32, "translation", "VEC3"),
    ):
        const = (
            np.all(values == values[:, :1], axis=(1, 2)) if times.count > 1 else np.zeros(len(nodes), bool)
        )
        width = values.shape[2] * 4
        accs: dict[int, tuple[int, int]] = {}
        varying = np.flatnonzero(~const)
        if varying.size:
            view = b.view(np.ascontiguousarray(values[varying]))
            for k, j in enumerate(varying.tolist()):
                accs[j] = (times.frames, b.accessor(view, k * times.count * width, FLOAT, times.count, kind))
        steady = np.flatnonzero(const)
        if steady.size:
            view = b.view(np.ascontiguousarray(values[steady, :1]))
            for k, j in enumerate(steady.tolist()):
                accs[j] = (times.one, b.accessor(view, k * width, FLOAT, 1, kind))
        for k, node in enumerate(nodes.tolist()):
            t_acc, acc = accs[k]
            channels.append({"sampler": len(samplers), "target": {"node": base + node, "path": path}})
            samplers.append({"input": t_acc, "interpolation": "LINEAR", "output": acc})


def _ibm(b: _Builder, rest: _Rest) -> int:
    """The inverse bind matrices accessor: the inverses of the rest globals, column-major."""
    ibm = np.linalg.inv(rest.globals)
    ibm[:, 3] = [0.0, 0.0, 0.0, 1.0]
    view = b.view(np.ascontiguousarray(np.swapaxes(ibm, 1, 2)).astype(np.float32))  # column-major
    return b.accessor(view, 0, FLOAT, len(ibm), "MAT4")


def write_glb(
    motion: Motion,
    path: str | Path,
    *,
    ground_root: bool = True,
    mesh: bool = True,
    in_place: bool = False,
    events: Sequence[dict[str, Any]] | None = None,
) -> None:
    """Write :func:`glb_bytes` of the motion to ``path`` (conventionally ``*.glb``).

    Parameters
    ----------
    motion, ground_root, mesh, in_place, events:
        As for :func:`glb_bytes`.
    path:
        Destination file, overwritten if it exists.

    Raises
    ------
    ExportError
        For a motion that cannot be exported (see :func:`glb_bytes`) or a file that cannot be
        written.
    """
    data = glb_bytes(motion, ground_root=ground_root, mesh=mesh, in_place=in_place, events=events)
    p = Path(path)
    try:
        p.write_bytes(data)
    except OSError as exc:
        raise ExportError(f"cannot write {p}: {exc.strerror or exc}") from None


# ------------------------------------------------------------------------------------------------
# helpers
# ------------------------------------------------------------------------------------------------


def _label(motion: Motion) -> str:
    return motion.name or "motion"


def _floats(v: npt.ArrayLike) -> list[float]:
    """A JSON list of the values as float32 numbers would store them."""
    return [float(x) for x in np.asarray(v, dtype=np.float32).reshape(-1)]


def _prepared(motion: Motion, ground_root: bool, name: str | None = None) -> Motion:
    """Validate the motion and add the ground root (``name``, default ``"ground"``) when asked
    (:class:`ExportError` otherwise)."""
    name = GROUND_ROOT_NAME if name is None else name
    if motion.num_frames == 0:
        raise ExportError(f"cannot export {_label(motion)}: it has no frames")
    if motion.num_joints > _MAX_SKIN_JOINTS - (1 if ground_root else 0):
        raise ExportError(f"cannot export {_label(motion)}: glTF skins here hold at most 65,536 joints")
    sk = motion.skeleton
    arrays = (motion.root_positions, motion.rotations, motion.joint_translations)
    if not all(np.all(np.isfinite(a)) for a in (*arrays, sk.offsets, sk.end_site_offsets)):
        raise ExportError(f"cannot export {_label(motion)}: it holds non-finite values (NaN or inf)")
    if not ground_root or sk.names[0] == name:
        return motion
    try:
        return add_ground_root(motion, name=name)
    except MotionError as exc:
        raise ExportError(f"cannot add a ground root to {_label(motion)}: {exc}") from None


def _bone_mesh(
    parents: npt.NDArray[np.intp],
    rest: Array,
    end_parents: npt.NDArray[np.intp],
    end_points: Array,
    lead: int,
) -> tuple[Array, Array, npt.NDArray[np.intp]] | None:
    """Flat-shaded octahedra along the rest-pose bones.

    Parameters
    ----------
    parents:
        ``(J,)`` parent joint indices.
    rest:
        ``(J, 3)`` global rest positions, metres.
    end_parents, end_points:
        ``(E,)`` joint and ``(E, 3)`` rest position (metres) of each End Site.
    lead:
        Joints ``0 .. lead-1`` are the ground root (and the in-place origin): their links to their
        children are not drawn.

    Returns
    -------
    positions, normals:
        ``(V, 3)`` vertices (metres, rest pose) and unit face normals, ``V = 24 B`` for ``B``
        bones (8 triangles of 3 own vertices each, counter-clockwise seen from outside).
    joints:
        ``(V,)`` the joint each vertex is bound to (the bone's parent).
    ``None`` when there is no bone to draw.
    """
    child = np.arange(1, len(parents))
    par = parents[1:]
    if lead:
        keep = par >= lead
        child, par = child[keep], par[keep]
    head = np.concatenate((rest[par], rest[end_parents]))
    tail = np.concatenate((rest[child], end_points))
    owner = np.concatenate((par, end_parents)).astype(np.intp)
    points = np.concatenate((rest, end_points))
    body = float(np.max(points.max(axis=0) - points.min(axis=0)))
    vec = tail - head
    length = np.linalg.norm(vec, axis=-1)
    keep = length > _MIN_BONE_OF_BODY * body
    if body <= 0.0 or not np.any(keep):
        return None
    head, tail, owner, vec, length = head[keep], tail[keep], owner[keep], vec[keep], length[keep]

    d = vec / length[:, None]
    helper = np.eye(3)[np.argmin(np.abs(d), axis=1)]  # world axis least aligned with the bone
    u = np.cross(d, helper)
    u /= np.linalg.norm(u, axis=-1, keepdims=True)
    v = np.cross(d, u)
    half = 0.5 * np.minimum(BONE_WIDTH_OF_BODY * body, BONE_WIDTH_OF_LENGTH * length)[:, None]
    waist = head + BONE_WAIST * vec
    ring = waist[:, None] + half[:, None] * np.stack((u, v, -u, -v), axis=1)  # (B, 4, 3)
    nxt = np.roll(ring, -1, axis=1)
    apex = np.stack((np.repeat(head[:, None], 4, axis=1), np.repeat(tail[:, None], 4, axis=1)), axis=1)
    a = apex  # (B, 2, 4, 3): head fan, tail fan
    b = np.stack((nxt, ring), axis=1)
    c = np.stack((ring, nxt), axis=1)
    tri = np.stack((a, b, c), axis=-2).reshape(-1, 8, 3, 3)  # (B, 8 faces, 3 corners, xyz)
    n = np.cross(tri[:, :, 1] - tri[:, :, 0], tri[:, :, 2] - tri[:, :, 0])
    outward = np.sum(n * (tri.mean(axis=2) - waist[:, None]), axis=-1) >= 0  # waist is inside
    flipped = tri[:, :, [0, 2, 1]]
    tri = np.where(outward[..., None, None], tri, flipped)
    n = np.where(outward[..., None], n, -n)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    positions = tri.reshape(-1, 3)
    normals = np.repeat(n, 3, axis=1).reshape(-1, 3)
    joints = np.repeat(owner, 24)
    return positions, normals, joints


def _skin_mesh(sk: Skeleton, rest: _Rest, lead: int, mesh: bool | MeshKind) -> SkinnedMesh | None:
    """The mesh of one skin in its bind pose: the bone octahedra (rigid), the mannequin body, or
    none."""
    if mesh is False:
        return None
    points = rest.globals[:, :3, 3]
    if mesh == "body":
        return body_mesh(sk, points, rest.ends, skip=lead)
    geometry = _bone_mesh(sk.parents, points, sk.end_site_parents, rest.ends, lead)
    if geometry is None:
        return None
    positions, normals, owner = geometry
    n = len(positions)
    joints = np.zeros((n, 4), dtype=np.uint16)
    joints[:, 0] = owner
    weights = np.zeros((n, 4), dtype=np.float32)
    weights[:, 0] = 1.0
    return SkinnedMesh(positions, normals, joints, weights, np.arange(n, dtype=np.uint32).reshape(-1, 3))


def _primitive(b: _Builder, mesh: SkinnedMesh) -> dict[str, Any]:
    """Write a skinned mesh's vertex attributes and indices; return the primitive JSON."""
    n = mesh.num_vertices
    pos32 = mesh.positions.astype(np.float32)
    flat = mesh.indices.reshape(-1)
    index = flat.astype(np.uint16 if n <= 65535 else np.uint32)
    attributes = {
        "POSITION": b.accessor(
            b.view(pos32, ARRAY_BUFFER), 0, FLOAT, n, "VEC3", pos32.min(axis=0), pos32.max(axis=0)
        ),
        "NORMAL": b.accessor(b.view(mesh.normals.astype(np.float32), ARRAY_BUFFER), 0, FLOAT, n, "VEC3"),
        "JOINTS_0": b.accessor(
            b.view(mesh.joints.astype(np.uint16), ARRAY_BUFFER), 0, UNSIGNED_SHORT, n, "VEC4"
        ),
        "WEIGHTS_0": b.accessor(b.view(mesh.weights.astype(np.float32), ARRAY_BUFFER), 0, FLOAT, n, "VEC4"),
    }
    index_type = UNSIGNED_SHORT if index.dtype == np.uint16 else UNSIGNED_INT
    indices = b.accessor(b.view(index, ELEMENT_ARRAY_BUFFER), 0, index_type, len(index), "SCALAR")
    return {"attributes": attributes, "indices": indices, "material": 0, "mode": 4}


class _Builder:
    """Accumulates the binary buffer, its buffer views and accessors."""

    def __init__(self) -> None:
        self.data = bytearray()
        self.views: list[dict[str, Any]] = []
        self.accessors: list[dict[str, Any]] = []

    def view(self, array: npt.NDArray[Any], target: int | None = None) -> int:
        """Append ``array`` (little-endian, C order) on a 4-byte boundary; return its view index."""
        self.data.extend(b"\0" * (-len(self.data) % 4))
        raw = np.ascontiguousarray(array, dtype=array.dtype.newbyteorder("<")).tobytes()
        view: dict[str, Any] = {"buffer": 0, "byteOffset": len(self.data), "byteLength": len(raw)}
        if target is not None:
            view["target"] = target
        self.data.extend(raw)
        self.data.extend(b"\0" * (-len(self.data) % 4))
        self.views.append(view)
        return len(self.views) - 1

    def accessor(
        self,
        view: int,
        offset: int,
        component: int,
        count: int,
        kind: str,
        lo: npt.ArrayLike | None = None,
        hi: npt.ArrayLike | None = None,
    ) -> int:
        """Add an accessor of ``count`` ``kind`` elements at byte ``offset`` (a multiple of 4)."""
        acc: dict[str, Any] = {
            "bufferView": view,
            "componentType": component,
            "count": count,
            "type": kind,
        }
        if offset:
            acc["byteOffset"] = offset
        if lo is not None and hi is not None:
            acc["min"] = _floats(lo)
            acc["max"] = _floats(hi)
        self.accessors.append(acc)
        return len(self.accessors) - 1


def _container(gltf: dict[str, Any], binary: bytes) -> bytes:
    """The GLB file: header, JSON chunk (space-padded), BIN chunk (zero-padded)."""
    text = json.dumps(gltf, ensure_ascii=False, separators=(",", ":"), allow_nan=False).encode("utf-8")
    text += b" " * (-len(text) % 4)
    binary += b"\0" * (-len(binary) % 4)
    total = 12 + 8 + len(text) + 8 + len(binary)
    if total >= 1 << 32:
        raise ExportError(f"the GLB file would be {total} bytes, over the 4 GiB limit of the format")
    return b"".join(
        (
            struct.pack("<4sII", GLB_MAGIC, GLB_VERSION, total),
            struct.pack("<II", len(text), CHUNK_JSON),
            text,
            struct.pack("<II", len(binary), CHUNK_BIN),
            binary,
        )
    )
