"""Several characters in one motion: the combined skeleton of crowds and couples, split apart.

Engines that move several characters at once (a rhythm crowd, a couple) return ONE motion whose
skeleton has a static root named ``"world"`` (identity rotation, at the origin) and under it one
subtree per character, each joint's name prefixed with the character (``c0_hip``, ``c1_hip``,
``c0_lead_hip``, ...). BVH keeps that combined skeleton (a BVH file has one hierarchy); GLB gives
each character its own skin (:func:`split_characters`), so that a game engine sees separate
characters and the file grows linearly with their number.
"""

from __future__ import annotations

import os
from dataclasses import replace

import numpy as np

from ..errors import MotionError
from ..motion import Motion
from ..skeleton import Skeleton

COMBINED_ROOT_NAME = "world"


def _subtree(parents: np.ndarray, root: int) -> np.ndarray:
    """Joint indices of ``root`` and its descendants, in skeleton order (parents before children)."""
    inside = np.zeros(parents.size, dtype=bool)
    inside[root] = True
    for j in range(root + 1, parents.size):  # parents come before their children
        if parents[j] >= 0 and inside[parents[j]]:
            inside[j] = True
    return np.flatnonzero(inside)


def character_prefix(names: tuple[str, ...] | list[str]) -> str:
    """The common name prefix of a character's joints up to its last ``_`` (``"c3_"``), or ``""``."""
    common = os.path.commonprefix(list(names))
    cut = common.rfind("_")
    return common[: cut + 1] if cut >= 0 else ""


def without_prefix(motion: Motion) -> tuple[Motion, str]:
    """The motion with its joints' common prefix (:func:`character_prefix`) taken off the names,
    and that prefix: what finds feet, sides and hips by name (contacts, heading, rest pose) reads
    ``lThigh``, not ``c0_lThigh``."""
    sk = motion.skeleton
    pre = character_prefix(sk.names)
    if not pre:
        return motion, ""
    plain = replace(sk, names=tuple(n[len(pre) :] for n in sk.names))
    return replace(motion, skeleton=plain), pre


def split_characters(motion: Motion, atol: float = 1e-9) -> list[Motion] | None:
    """The characters of a combined motion (module docstring), each a motion of its own skeleton.

    Returns ``None`` for a motion that is not combined: its root is not a static ``"world"`` joint
    with child subtrees (a crowd of one is a character too). Each character's root gets the
    world-space translation it had (the static world root being the identity), its names keep
    their prefix, and it keeps the motion's fps, units and name (suffixed with the prefix).
    """
    sk = motion.skeleton
    if sk.names[0] != COMBINED_ROOT_NAME:
        return None
    kids = sk.children(0)
    if not kids:
        return None
    q0 = motion.rotations[:, 0]
    if not (
        np.allclose(np.abs(q0[:, 3]), 1.0, atol=1e-7) and np.allclose(motion.root_positions, 0.0, atol=atol)
    ):
        return None
    local = motion.local_translations()
    out: list[Motion] = []
    for kid in kids:
        idx = _subtree(sk.parents, kid)
        remap = {int(j): k for k, j in enumerate(idx)}
        parents = np.array([-1] + [remap[int(sk.parents[j])] for j in idx[1:]], dtype=np.intp)
        es = np.flatnonzero(np.isin(sk.end_site_parents, idx))
        names = tuple(sk.names[j] for j in idx)
        sub = Skeleton(
            names,
            parents,
            sk.offsets[idx],
            tuple(sk.channels[j] for j in idx),
            np.array([remap[int(p)] for p in sk.end_site_parents[es]], dtype=np.intp),
            sk.end_site_offsets[es],
        )
        prefix = character_prefix(names)
        out.append(
            Motion(
                sub,
                local[:, kid],
                motion.rotations[:, idx],
                motion.fps,
                joint_translations=local[:, idx[sub.translated_joints]],
                units=motion.units,
                name=f"{motion.name or 'motion'}_{prefix.rstrip('_') or len(out)}",
            )
        )
    return out


def combine_characters(motions: list[Motion], prefixes: list[str]) -> Motion:
    """Several characters (same frame count, fps and units) as one combined motion: a static
    ``"world"`` root and each character's joints, names prefixed, its root translated from the
    world (the inverse of :func:`split_characters`; the layout the engines' crowds use)."""
    if not motions or len(motions) != len(prefixes):
        raise MotionError("combine_characters needs one prefix per motion, and at least one motion")
    first = motions[0]
    if any(m.num_frames != first.num_frames or m.fps != first.fps or m.units != first.units for m in motions):
        raise MotionError("the characters to combine differ in frame count, fps or units")
    pos = ("Xposition", "Yposition", "Zposition")
    names: list[str] = [COMBINED_ROOT_NAME]
    parents: list[int] = [-1]
    offsets = [np.zeros((1, 3))]
    channels: list[tuple[str, ...]] = [(*pos, "Zrotation", "Yrotation", "Xrotation")]
    es_par, es_off, rots, trans = [], [], [np.tile([0.0, 0.0, 0.0, 1.0], (first.num_frames, 1, 1))], []
    for m, pre in zip(motions, prefixes, strict=True):
        sk, base = m.skeleton, len(names)
        names += [pre + n for n in sk.names]
        parents += [0] + [int(p) + base for p in sk.parents[1:]]
        offsets.append(sk.offsets)
        root_rot = tuple(c for c in sk.channels[0] if c.endswith("rotation"))
        channels += [(*pos, *root_rot), *sk.channels[1:]]
        es_par.append(sk.end_site_parents + base)
        es_off.append(sk.end_site_offsets)
        rots.append(m.rotations)
        lt = m.local_translations()
        trans.append(lt[:, [0, *sk.translated_joints.tolist()]])
    sk = Skeleton(
        tuple(names),
        np.array(parents, dtype=np.intp),
        np.concatenate(offsets),
        tuple(channels),
        np.concatenate(es_par).astype(np.intp),
        np.concatenate(es_off).reshape(-1, 3),
    )
    return Motion(
        sk,
        np.zeros((first.num_frames, 3)),
        np.concatenate(rots, axis=1),
        first.fps,
        joint_translations=np.concatenate(trans, axis=1),
        units=first.units,
        name=first.name,
    )
