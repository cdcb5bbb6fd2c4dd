"""Reading a glTF 2.0 animation (GLB, or ``.gltf`` with its buffers) as a :class:`Motion`.

A glTF file is a motion input when it holds a skin (the skeleton: ``skins[k].joints``) and an
animation whose channels move that skin's joints. :func:`gltf_animations` lists every animation
(name, frames, rate, the skin it moves); :func:`parse_gltf` reads one, picked by name or index.

What is read
------------
Joints
    The skin's joints (the skin the animation moves most), each after its parent (the skin's own
    order otherwise), named after their nodes (``joint<i>`` for a node without a name).
End Sites
    Leaf nodes under a joint that are not joints themselves and carry no mesh, camera or skin
    (Segue writes ``<joint>_end`` nodes; Blender, Mixamo and others write ``*_end`` / ``*Top_End``
    leaves or none).
Frames
    One frame every ``1 / fps`` seconds from the animation's first key to its last, ``fps`` the
    rate of its densest sampler (snapped to an integer rate within 0.1 %): a file Segue wrote
    gives back its frames exactly. Each channel is sampled at those times as glTF says: ``LINEAR``
    (translations and scales interpolated linearly, rotations by slerp), ``STEP`` and
    ``CUBICSPLINE`` (Hermite, rotations normalised after); before its first key and after its
    last a channel holds its end value, and a node without a channel for a property keeps its
    node's own value.
Poses
    Every joint's global position and rotation are computed per frame from the node transforms,
    including the non-joint nodes above the skin (an ``Armature`` node's 0.01 scale or its Z-up
    turn is applied), so the motion is in metres, Y up, as glTF is. The BVH-style skeleton takes
    each joint's bone vector in its parent's frame as its offset; a joint whose bone vector
    changes over the animation (a translation channel that moves, a scale channel) gets position
    channels and carries it per frame, so joint positions are exact either way. A non-uniform
    scale cannot be represented (rotations are read without it; a warning says so).
Segue's own GLBs
    The ``ground`` root Segue adds for game engines' root motion
    (:func:`motion.ground.add_ground_root`; ``cN_ground`` for each character of a crowd) is folded
    back into the body root below it, and an in-place file's static ``origin`` root
    (:mod:`motion.export.glb`) likewise: ``segue convert walk.bvh walk.glb`` then ``walk.glb
    back.bvh`` gives the joints, End Sites and frames of ``walk.bvh`` (positions within 1e-6 m:
    GLB holds float32).

Everything else a glTF file holds (meshes, materials, morph targets, cameras) is ignored.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from . import rotations as rot
from .errors import ReadWarning
from .gltf_file import GltfFile
from .motion import Motion
from .skeleton import DEFAULT_JOINT_CHANNELS, DEFAULT_ROOT_CHANNELS, Skeleton

Array = npt.NDArray[np.float64]

GLTF_SUFFIXES = (".glb", ".gltf")
_FPS_SNAP = 1e-3
_MOVING_BONE_M = 1e-6
"""A bone vector that changes by more than this over the animation (metres) makes its joint a
translated one (position channels)."""
_POSITIONS = ("Xposition", "Yposition", "Zposition")
_PATHS = {"translation": 3, "rotation": 4, "scale": 3}


def is_gltf(data: bytes) -> bool:
    """Whether ``data`` looks like a glTF file: a GLB container or a JSON document."""
    return data[:4] == b"glTF" or data.lstrip()[:1] == b"{"


@dataclass(frozen=True, slots=True)
class GltfAnimation:
    """One animation of a glTF file: its ``index`` and ``name`` (``animation<i>`` when unnamed),
    ``frames`` at ``fps`` (as :func:`parse_gltf` reads it), ``duration_s`` (first key to last),
    and the ``skin`` it moves (index; ``-1`` when it moves no skin's joints: not a motion)."""

    index: int
    name: str
    frames: int
    fps: float
    duration_s: float
    skin: int


def _animations(doc: GltfFile) -> list[dict[str, Any]]:
    anims = doc.doc.get("animations") or []
    if not isinstance(anims, list):
        raise doc.error("'animations' is not a list")
    return anims


def _anim_name(anim: dict[str, Any], index: int) -> str:
    return str(anim.get("name") or f"animation{index}")


def _skin_of(doc: GltfFile, anim: dict[str, Any]) -> int:
    """The skin whose joints the animation's channels move most (``-1``: none)."""
    targets = {int(c["target"]["node"]) for c in anim.get("channels") or [] if "node" in c.get("target", {})}
    best, most = -1, 0
    for k, skin in enumerate(doc.doc.get("skins") or []):
        joints = {int(j) for j in skin.get("joints") or []}
        moved = len(joints & targets)
        if moved > most:
            best, most = k, moved
    return best


def _timing(doc: GltfFile, anim: dict[str, Any]) -> tuple[float, float, int]:
    """``(start_s, fps, frames)`` of an animation (module docstring, *Frames*)."""
    starts, ends, rate = [], [], 0.0
    for sampler in anim.get("samplers") or []:
        times = doc.accessor(int(sampler["input"]))[:, 0]
        if times.size == 0:
            continue
        if np.any(np.diff(times) <= 0):
            raise doc.error(f"animation {_anim_name(anim, 0)!r}: a sampler's key times do not increase")
        starts.append(float(times[0]))
        ends.append(float(times[-1]))
        if times.size > 1:
            rate = max(rate, 1.0 / float(np.median(np.diff(times))))
    if not starts:
        return 0.0, 30.0, 1
    start, end = min(starts), max(ends)
    fps = rate if rate > 0 else 30.0
    if abs(fps - round(fps)) <= _FPS_SNAP * fps:
        fps = float(round(fps))
    return start, fps, int(round((end - start) * fps)) + 1


def gltf_animations(
    raw: bytes, *, base_dir: str | Path | None = None, source: str = "<bytes>"
) -> list[GltfAnimation]:
    """Every animation of a glTF/GLB file (see :class:`GltfAnimation`), in file order."""
    doc = GltfFile.read(raw, base_dir, source)
    out = []
    for i, anim in enumerate(_animations(doc)):
        start, fps, frames = _timing(doc, anim)
        out.append(
            GltfAnimation(
                i, _anim_name(anim, i), frames, fps, round((frames - 1) / fps, 6), _skin_of(doc, anim)
            )
        )
    return out


def _pick(doc: GltfFile, animation: str | int | None) -> tuple[int, dict[str, Any]]:
    anims = _animations(doc)
    names = [_anim_name(a, i) for i, a in enumerate(anims)]
    if not anims:
        raise doc.error(
            "the glTF file has no animation: a motion needs one (a character's skin alone is read by "
            "segue retarget --to)"
        )
    listed = ", ".join(f"{i}: {n!r}" for i, n in enumerate(names))
    if animation is None:
        return 0, anims[0]
    if isinstance(animation, int) or (
        isinstance(animation, str) and animation.isdigit() and animation not in names
    ):
        k = int(animation)
        if not 0 <= k < len(anims):
            raise doc.error(f"no animation {k}: the file has {len(anims)} ({listed})")
        return k, anims[k]
    if animation not in names:
        raise doc.error(f"no animation named {animation!r}; the file has {listed}")
    k = names.index(animation)
    return k, anims[k]


def _sample(doc: GltfFile, sampler: dict[str, Any], path: str, grid: Array) -> Array:
    """A sampler's values at the times ``grid (F,)``: ``(F, 3 or 4)`` (module docstring)."""
    times = doc.accessor(int(sampler["input"]))[:, 0]
    values = doc.accessor(int(sampler["output"]))
    width = _PATHS[path]
    mode = str(sampler.get("interpolation", "LINEAR"))
    if values.shape[1] != width:
        raise doc.error(f"a {path} sampler's output has {values.shape[1]} components, expected {width}")
    n = times.size
    if mode == "CUBICSPLINE":
        if values.shape[0] != 3 * n:
            raise doc.error("a CUBICSPLINE sampler needs 3 outputs (in-tangent, value, out-tangent) per key")
        a_in, v, b_out = values[0::3], values[1::3], values[2::3]
    else:
        if values.shape[0] != n:
            raise doc.error(f"a sampler has {n} key times and {values.shape[0]} values")
        v = values
    if n == 1:
        out = np.repeat(v[:1], grid.size, axis=0)
    elif mode == "STEP":
        # key times are float32: a frame within a microsecond of a key is at that key
        k = np.clip(np.searchsorted(times, grid + 1e-6, side="right") - 1, 0, n - 1)
        out = v[k]
    else:
        k = np.clip(np.searchsorted(times, grid, side="right") - 1, 0, n - 2)
        dt = times[k + 1] - times[k]
        u = np.clip((grid - times[k]) / dt, 0.0, 1.0)
        if mode == "CUBICSPLINE":
            u2, u3 = u * u, u * u * u
            h = (2 * u3 - 3 * u2 + 1, (u3 - 2 * u2 + u) * dt, -2 * u3 + 3 * u2, (u3 - u2) * dt)
            out = (
                h[0][:, None] * v[k]
                + h[1][:, None] * b_out[k]
                + h[2][:, None] * v[k + 1]
                + h[3][:, None] * a_in[k + 1]
            )
        elif mode == "LINEAR":
            if path == "rotation":
                out = rot.slerp(rot.normalize(v[k]), rot.normalize(v[k + 1]), u)
            else:
                out = v[k] + u[:, None] * (v[k + 1] - v[k])
        else:
            raise doc.error(f"unknown interpolation {mode!r}")
    if path == "rotation":
        norms = np.linalg.norm(out, axis=1, keepdims=True)
        if np.any(norms <= 0):
            raise doc.error("a rotation sampler holds a zero quaternion")
        out = out / norms
    return np.asarray(out, dtype=np.float64)


def parse_gltf(
    raw: bytes,
    *,
    animation: str | int | None = None,
    name: str | None = None,
    source: str = "<bytes>",
    base_dir: str | Path | None = None,
    max_joints: int = 1024,
    max_joint_frames: int = 20_000_000,
    warnings: list[ReadWarning] | None = None,
) -> Motion:
    """One animation of a glTF/GLB file as a motion in metres (module docstring).

    Parameters
    ----------
    raw:
        The file's bytes (GLB, or ``.gltf`` JSON whose buffers are ``data:`` URIs or files in
        ``base_dir``).
    animation:
        Its name or index (default: the first animation).
    name:
        Name recorded on the motion (default: the animation's name).
    max_joints, max_joint_frames:
        Limits on the skin's joints and on frames x joints (:class:`motion.bvh.BvhLimits`).
    warnings:
        When given, what was read with a loss (a non-uniform scale) is appended to it.

    Raises
    ------
    MotionError
        Naming ``source``: not glTF, no animation or no such animation, no skin the animation
        moves, malformed accessors or samplers, or a limit exceeded.
    """
    doc = GltfFile.read(raw, base_dir, source)
    index, anim = _pick(doc, animation)
    label = _anim_name(anim, index)
    skin_index = _skin_of(doc, anim)
    if skin_index < 0:
        if not doc.doc.get("skins"):
            raise doc.error("the glTF file has no skin: a motion needs a skinned skeleton")
        raise doc.error(f"animation {label!r} moves none of the skins' joints")
    skin = doc.doc["skins"][skin_index]
    order, parents = doc.skin_tree([int(j) for j in skin["joints"]])
    if len(order) > max_joints:
        raise doc.error(f"the skin has {len(order)} joints, more than the {max_joints}-joint limit")
    start, fps, frames = _timing(doc, anim)
    if frames * len(order) > max_joint_frames:
        raise doc.error(
            f"animation {label!r}: {frames} frames x {len(order)} joints is over the {max_joint_frames:,} "
            "joint-frame limit"
        )
    grid = start + np.arange(frames, dtype=np.float64) / fps

    # nodes whose transforms make the joints' globals: the joints, their ancestors and End Sites
    needed: set[int] = set()
    for j in order:
        n: int | None = j
        while n is not None and n not in needed:
            needed.add(n)
            n = doc.parent.get(n)
    joint_set = set(order)
    sites = [
        c
        for j in order
        for c in (int(x) for x in doc.nodes[j].get("children") or [])
        if c not in joint_set
        and not doc.nodes[c].get("children")
        and not any(k in doc.nodes[c] for k in ("mesh", "camera", "skin"))
    ]
    needed.update(sites)
    tracks: dict[tuple[int, str], Array] = {}
    for ch in anim.get("channels") or []:
        target = ch.get("target") or {}
        node, path = target.get("node"), target.get("path")
        if node is None or int(node) not in needed or path not in _PATHS:
            continue  # other nodes' channels, morph weights
        try:
            sampler = anim["samplers"][int(ch["sampler"])]
        except (IndexError, KeyError, TypeError, ValueError):
            raise doc.error(f"animation {label!r}: a channel names a missing sampler") from None
        tracks[(int(node), str(path))] = _sample(doc, sampler, str(path), grid)

    # global position, rotation (scale left out) and scale of every needed node, per frame
    wpos: dict[int, Array] = {}
    wrot: dict[int, Array] = {}
    wscale: dict[int, Array] = {}
    uneven = False

    def world(i: int) -> None:
        if i in wpos:
            return
        t0, q0, s0 = doc.local(i)
        t = tracks.get((i, "translation"), np.broadcast_to(t0, (frames, 3)))
        q = tracks.get((i, "rotation"), np.broadcast_to(q0, (frames, 4)))
        s = tracks.get((i, "scale"), np.broadcast_to(s0, (frames, 3)))
        p = doc.parent.get(i)
        if p is None:
            wpos[i], wrot[i], wscale[i] = np.array(t), np.array(q), np.array(s)
            return
        world(p)
        wpos[i] = wpos[p] + rot.rotate(wrot[p], wscale[p] * t)
        wrot[i] = rot.multiply(wrot[p], q)
        wscale[i] = wscale[p] * s

    try:
        for i in sorted(needed, key=lambda k: _depth(doc, k)):
            world(i)
    except RecursionError:
        raise doc.error("the node hierarchy is too deep or has a cycle") from None
    for i in order:
        sc = wscale[i]
        if np.any(np.abs(sc - sc[:, :1]) > 1e-6 * np.abs(sc[:, :1]).max(initial=1.0)):
            uneven = True

    names = [doc.name(i) for i in order]
    if len(set(names)) != len(names):
        raise doc.error("the skin's joint names are not unique")
    par = np.array(parents, dtype=np.intp)
    motion = _as_motion(order, par, names, sites, doc, wpos, wrot, fps, label if name is None else name)
    motion = _without_segue_roots(motion)
    if uneven and warnings is not None:
        warnings.append(
            ReadWarning(
                "nonuniform_scale",
                f"animation {label!r}: a joint is scaled unevenly along its axes, which a skeleton cannot "
                "hold; joint positions are exact, rotations are read without the scale",
                None,
                source,
            )
        )
    return motion


def _depth(doc: GltfFile, i: int) -> int:
    d = 0
    while i in doc.parent and d <= len(doc.nodes):
        i = doc.parent[i]
        d += 1
    return d


def _as_motion(
    order: list[int],
    parents: npt.NDArray[np.intp],
    names: list[str],
    sites: list[int],
    doc: GltfFile,
    wpos: dict[int, Array],
    wrot: dict[int, Array],
    fps: float,
    name: str,
) -> Motion:
    """The joints' global poses as a BVH-style motion: offsets are the bone vectors in the
    parent's frame, joints whose bone vector moves get position channels."""
    n_joints = len(order)
    frames = wpos[order[0]].shape[0]
    gpos = np.stack([wpos[i] for i in order], axis=1)  # (F, J, 3)
    grot = np.stack([wrot[i] for i in order], axis=1)  # (F, J, 4)
    local = grot.copy()
    bones = np.zeros((frames, n_joints, 3))
    child = np.flatnonzero(parents >= 0)
    pj = parents[child]
    inv = rot.conjugate(grot[:, pj])
    local[:, child] = rot.multiply(inv, grot[:, child])
    bones[:, child] = rot.rotate(inv, gpos[:, child] - gpos[:, pj])
    moving = np.zeros(n_joints, dtype=bool)
    moving[child] = np.max(np.abs(bones[:, child] - bones[:1, child]), axis=(0, 2)) > _MOVING_BONE_M
    offsets = bones[0].copy()
    offsets[0] = gpos[0, 0]
    channels: list[tuple[str, ...]] = [DEFAULT_ROOT_CHANNELS]
    for j in range(1, n_joints):
        channels.append((*_POSITIONS, *DEFAULT_JOINT_CHANNELS) if moving[j] else DEFAULT_JOINT_CHANNELS)
    site_parents = np.array([order.index(doc.parent[s]) for s in sites], dtype=np.intp)
    site_offsets = np.zeros((len(sites), 3))
    for k, s in enumerate(sites):
        p = order.index(doc.parent[s])
        site_offsets[k] = rot.rotate(rot.conjugate(grot[0, p]), wpos[s][0] - gpos[0, p])
    keep = np.argsort(site_parents, kind="stable")
    skeleton = Skeleton(
        tuple(names), parents, offsets, tuple(channels), site_parents[keep], site_offsets[keep]
    )
    translated = skeleton.translated_joints
    return Motion(
        skeleton,
        gpos[:, 0].copy(),
        local,
        fps,
        joint_translations=bones[:, translated].copy(),
        units="m",
        name=name,
    )


def _without_segue_roots(motion: Motion) -> Motion:
    """The motion without the roots Segue's GLB export adds (module docstring): a ``ground`` root
    (``cN_ground`` for a character of a crowd) with one child joint, or an ``origin`` root over
    ``ground`` and the body (in place)."""
    from .ground import GROUND_ROOT_NAME

    sk = motion.skeleton
    names = sk.names
    kids = [int(c) for c in np.flatnonzero(sk.parents == 0)]
    if names[0] == "origin" and len(kids) == 2 and names[kids[0]] == GROUND_ROOT_NAME:
        ground, body = kids
        if int(np.count_nonzero(sk.parents == ground)) == 0:  # in place: put the body back on the ground
            pos, grot = motion.fk()
            keep = [j for j in range(sk.num_joints) if j not in (0, ground)]
            return _rerooted(motion, keep, body, _compose(pos, grot, ground, body, motion))
    grounded = names[0] == GROUND_ROOT_NAME or names[0].endswith("_" + GROUND_ROOT_NAME)  # cN_ground
    if grounded and len(kids) == 1:
        pos, grot = motion.fk()
        keep = list(range(1, sk.num_joints))
        return _rerooted(motion, keep, kids[0], (pos[:, kids[0]], grot[:, kids[0]]))
    return motion


def _compose(pos: Array, grot: Array, ground: int, body: int, motion: Motion) -> tuple[Array, Array]:
    """The body root's global pose in an in-place file: its pose relative to the ground joint
    (what the file's hierarchy under the static origin holds) put back on the ground joint."""
    origin_rot = grot[:, 0]
    rel_pos = rot.rotate(rot.conjugate(origin_rot), pos[:, body] - pos[:, 0])
    rel_rot = rot.multiply(rot.conjugate(origin_rot), grot[:, body])
    return pos[:, ground] + rot.rotate(grot[:, ground], rel_pos), rot.multiply(grot[:, ground], rel_rot)


def _rerooted(motion: Motion, keep: Sequence[int], root: int, pose: tuple[Array, Array]) -> Motion:
    """The sub-skeleton of joints ``keep`` (``root`` first, the new root, at global ``pose``)."""
    sk = motion.skeleton
    keep = [root, *[j for j in keep if j != root]]
    index = {j: k for k, j in enumerate(keep)}
    parents = np.array([-1 if j == root else index[int(sk.parents[j])] for j in keep], dtype=np.intp)
    sites = np.array([i for i, p in enumerate(sk.end_site_parents) if int(p) in index], dtype=np.intp)
    channels = [DEFAULT_ROOT_CHANNELS, *[sk.channels[j] for j in keep[1:]]]
    offsets = sk.offsets[keep].copy()
    offsets[0] = pose[0][0]
    skeleton = Skeleton(
        tuple(sk.names[j] for j in keep),
        parents,
        offsets,
        tuple(channels),
        np.array([index[int(sk.end_site_parents[i])] for i in sites], dtype=np.intp),
        sk.end_site_offsets[sites] if sites.size else np.zeros((0, 3)),
    )
    rotations = motion.rotations[:, keep].copy()
    rotations[:, 0] = pose[1]
    old_slot = {int(j): k for k, j in enumerate(sk.translated_joints)}
    jt = (
        np.stack(
            [motion.joint_translations[:, old_slot[keep[int(j)]]] for j in skeleton.translated_joints], axis=1
        )
        if skeleton.translated_joints.size
        else np.zeros((motion.num_frames, 0, 3))
    )
    return Motion(skeleton, pose[0].copy(), rotations, motion.fps, jt, motion.units, motion.name)
