"""Several characters as one output motion: the combined skeleton every multi-character result uses.

A static ``world`` root (joint 0) with each character's skeleton under it, joint names prefixed
(``c0_``, ``c1_``...; rhythm couples ``c0_lead_``, ``c0_follow_``), each character's root
carrying position channels. BVH and the other exports write it as it is; the quality report
measures each character (:class:`motion.goals.Character`) on its own joints. Used by the rhythm
engine (crowds, couples) and the graph engine (characters with shared constraints).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import numpy.typing as npt

from motion import Motion, Skeleton
from motion.goals import Character
from motion.skeleton import POSITION_CHANNELS

from .base import EngineError

Array = npt.NDArray[np.float64]


def combined_skeleton(skeletons: list[Skeleton], prefixes: list[str]) -> Skeleton:
    """One skeleton holding several characters under a static ``world`` root (module doc)."""
    names: list[str] = ["world"]
    parents: list[int] = [-1]
    offsets: list[Array] = [np.zeros((1, 3))]
    channels: list[tuple[str, ...]] = [
        ("Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation", "Xrotation")
    ]
    es_par: list[npt.NDArray[np.intp]] = []
    es_off: list[Array] = []
    for sk, pre in zip(skeletons, prefixes, strict=True):
        base = len(names)
        names += [pre + n for n in sk.names]
        parents += [0] + [int(p) + base for p in sk.parents[1:]]
        offsets.append(sk.offsets)
        root_ch = tuple(c for c in sk.channels[0] if c.endswith("rotation"))
        channels += [POSITION_CHANNELS + root_ch, *sk.channels[1:]]
        es_par.append(sk.end_site_parents + base)
        es_off.append(sk.end_site_offsets)
    return Skeleton(
        tuple(names),
        np.array(parents),
        np.concatenate(offsets),
        tuple(channels),
        np.concatenate(es_par),
        np.concatenate(es_off),
    )


def combine_motions(motions: list[Motion], prefixes: list[str], name: str) -> Motion:
    """Motions of equal length and rate (metres) as one motion on :func:`combined_skeleton`: each
    character's root translation becomes the translation of its root joint under ``world``."""
    sk = combined_skeleton([m.skeleton for m in motions], prefixes)
    f = motions[0].num_frames
    if any(m.num_frames != f for m in motions):
        counts = sorted({m.num_frames for m in motions})
        raise EngineError(f"characters of {counts} frames cannot be combined")
    if any(m.joint_translations.shape[1] for m in motions):
        raise EngineError("several characters with animated non-root translations are not supported")
    rot = np.concatenate([np.tile([0.0, 0.0, 0.0, 1.0], (f, 1, 1))] + [m.rotations for m in motions], axis=1)
    jt = np.stack([m.root_positions for m in motions], axis=1)  # each character's root translation
    return replace(
        motions[0],
        skeleton=sk,
        root_positions=np.zeros((f, 3)),
        rotations=rot,
        joint_translations=jt,
        name=name,
    )


def combined_characters(skeletons: list[tuple[str, Skeleton]], motion: Motion) -> tuple[Character, ...]:
    """The characters ``(label, skeleton)`` of a combined output (:func:`combined_skeleton`:
    joint 0 is the static ``world``, then each character's joints in its own order)."""
    out: list[Character] = []
    base = 1
    for label, sk in skeletons:
        out.append(Character(np.arange(base, base + sk.num_joints, dtype=np.intp), sk, label))
        base += sk.num_joints
    if base != motion.num_joints:
        raise EngineError(f"the combined skeleton has {motion.num_joints} joints, the characters {base}")
    return tuple(out)
