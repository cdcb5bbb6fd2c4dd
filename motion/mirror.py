"""Left/right mirroring of motions, with left/right joints paired by name.

:func:`mirror` gives exactly the mirrored positions, in the skeleton's own conventions: each joint
of the image takes a frame (:func:`joint_frames`) that keeps its bones where they are and its
rotations like the joint's own, so a clip and a mirror image can be cut together and their
rotations blended (a T-pose rig keeps the plain reflection ``M L M``; Bandai-Namco's, whose bones
run along local x, does not). Clips mirrored together share one set of frames.
"""

from __future__ import annotations

import itertools
import re
from collections.abc import Mapping, Sequence
from dataclasses import replace
from functools import lru_cache
from typing import Any

import numpy as np
import numpy.typing as npt

from . import rotations as rot
from .errors import MotionError
from .motion import Motion
from .skeleton import Skeleton

_LEFT_TOKENS = {"Left", "left", "LEFT", "l", "L"}
_SWAP = {
    "Left": "Right",
    "Right": "Left",
    "left": "right",
    "right": "left",
    "LEFT": "RIGHT",
    "RIGHT": "LEFT",
    "l": "r",
    "r": "l",
    "L": "R",
    "R": "L",
}
_PAIR_PATTERNS: tuple[tuple[str, dict[str, str]], ...] = (
    (r"Left|Right|left|right|LEFT|RIGHT", _SWAP),
    (r"^[lrLR]", _SWAP),  # only when the swapped name exists: lShldr, L_Foot, lhand
    (r"(?<=[_.\-\s])[lrLR](?=$|[_.\-\s\d])", _SWAP),
)


def mirror_map(names: tuple[str, ...] | list[str]) -> tuple[npt.NDArray[np.intp], npt.NDArray[np.int8]]:
    """Pair left and right joints by name (found once per list of names; fresh arrays every call).

    Returns
    -------
    partner:
        ``(J,)`` index of each joint's mirror counterpart (itself when unpaired, e.g. the spine).
    side:
        ``(J,)`` +1 for left joints, -1 for right joints, 0 for unpaired ones.

    Recognised spellings: ``Left``/``Right`` anywhere (``LeftUpLeg``), a leading ``l``/``r`` or
    ``L``/``R`` (``lShldr``, ``L_Foot``, ``lhand``), and a trailing or
    separated ``l``/``r`` (``hand_l``, ``Hand.L``).
    """
    partner, side = _mirror_map(tuple(names))
    return partner.copy(), side.copy()


@lru_cache(maxsize=256)
def _mirror_map(names: tuple[str, ...]) -> tuple[npt.NDArray[np.intp], npt.NDArray[np.int8]]:
    index = {n: i for i, n in enumerate(names)}
    partner = np.arange(len(names), dtype=np.intp)
    side = np.zeros(len(names), dtype=np.int8)
    for i, name in enumerate(names):
        for pattern, repl in _PAIR_PATTERNS:
            m = re.search(pattern, name)
            if m is None:
                continue
            other = name[: m.start()] + repl[m.group(0)] + name[m.end() :]
            j = index.get(other)
            if j is not None and j != i:
                partner[i] = j
                side[i] = 1 if m.group(0) in _LEFT_TOKENS else -1
                break
    return partner, side


_SIDE_WORD = re.compile(r"(?<![A-Za-z])(?:left|right|LEFT|RIGHT)(?![A-Za-z])|(?:Left|Right)(?![a-z])")
"""A side named in a label: ``left``/``right`` (any case) as a word of its own (``wave-left-hand``,
``turn_right``, ``Walk Left``) or a capitalised part of a camel-case name (``raiseLeftHand``)."""


def mirror_label(label: str) -> str:
    """The label of a motion's mirror image: every side the label names exchanged (``left`` <->
    ``right``, case kept; see :data:`_SIDE_WORD`), so ``wave-left-hand`` becomes ``wave-right-hand``
    and ``walk-turn-right`` becomes ``walk-turn-left``; a label that names no side is returned as is
    (``walk``, ``bright``, ``leftover``)."""
    return _SIDE_WORD.sub(lambda m: _SWAP[m.group(0)], label)


def mirrored_labels(labels: Sequence[Mapping[str, Any]]) -> tuple[dict[str, Any], ...]:
    """A clip's label ranges (mappings with ``label``, ``start``, ``end``, ``value``) as its mirror
    image carries them: the same frames and values, each label's named side exchanged
    (:func:`mirror_label`: ``wave-left-hand`` -> ``wave-right-hand``; ``walk`` stays ``walk``)."""
    return tuple({**lb, "label": mirror_label(str(lb["label"]))} for lb in labels)


def reflect_vectors(v: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Reflect vectors ``(..., 3)`` across the YZ plane (x -> -x)."""
    out = np.array(v, dtype=np.float64, copy=True)
    out[..., 0] *= -1.0
    return out


def reflect_quaternions(q: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """The rotations ``M R M`` for the reflection ``M = diag(-1, 1, 1)``.

    In quaternions: ``(x, y, z, w) -> (x, -y, -z, w)``.
    """
    out = np.array(q, dtype=np.float64, copy=True)
    out[..., 1:3] *= -1.0
    return out


def _cube_rotations() -> npt.NDArray[np.float64]:
    """``(24, 4)`` the rotations that map the coordinate axes onto the axes (the cube's), as
    quaternions, the half turn about x (the plain reflection's, see :func:`joint_frames`) first."""
    mats = []
    for perm in itertools.permutations(range(3)):
        for signs in itertools.product((1.0, -1.0), repeat=3):
            m = np.zeros((3, 3))
            m[np.arange(3), perm] = signs
            if np.linalg.det(m) > 0:
                mats.append(m)
    q = rot.standardize(rot.from_matrix(np.array(mats)))
    first = int(np.argmax(np.abs(q @ _HALF_X)))
    return np.concatenate((_HALF_X[None], np.delete(q, first, axis=0)))


_HALF_X = np.array([1.0, 0.0, 0.0, 0.0])
"""The half turn about x: ``-M`` for the world's reflection ``M = diag(-1, 1, 1)``."""
_CUBE = _cube_rotations()
BONE_TOLERANCE = 0.05
"""A joint frame keeps the skeleton's bones when it moves none by more than this fraction of their
total length (:func:`joint_frames`)."""
PLAIN_MARGIN_RAD = float(np.radians(30.0))
""":func:`joint_frames` keeps the plain reflection unless another frame fits the rotations by this
much better."""


def _angles(q: npt.NDArray[np.float64], r: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Angles (radians) between rotations ``q (N, 4)`` and one rotation ``r (4,)``."""
    return np.asarray(2.0 * np.arccos(np.clip(np.abs(q @ r), 0.0, 1.0)))


def _mean_rotations(motions: Sequence[Motion]) -> npt.NDArray[np.float64]:
    """``(J, 4)`` the chordal mean of each joint's rotations over every frame of ``motions`` (signs
    aligned to the first frame's)."""
    ref: npt.NDArray[np.float64] | None = None
    total = None
    for m in motions:
        q = np.asarray(m.rotations, dtype=np.float64)
        if q.shape[0] == 0:
            continue
        if ref is None:
            ref = q[0]
        signs = np.sign(np.einsum("fjk,jk->fj", q, ref))
        signs[signs == 0] = 1.0
        part = (q * signs[..., None]).sum(axis=0)
        total = part if total is None else total + part
    if total is None or ref is None:
        raise MotionError("no frames to mirror")
    norm = np.linalg.norm(total, axis=-1, keepdims=True)
    return np.asarray(np.where(norm > 1e-12, total / np.maximum(norm, 1e-300), ref))


def _image_of(frame: npt.NDArray[np.float64], v: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """``-R^-1 v``: vectors ``v (..., 3)`` of a joint's frame in its mirror image's frame ``R`` (a
    quaternion; the plain reflection ``M v`` for the half turn about x, bit for bit)."""
    if np.array_equal(frame, _HALF_X):
        return reflect_vectors(v)
    return np.asarray(-rot.rotate(np.broadcast_to(rot.conjugate(frame), v.shape[:-1] + (4,)), v))


def joint_frames(motions: Motion | Sequence[Motion]) -> npt.NDArray[np.float64]:
    """``(J, 4)`` per joint, the frame ``R_j`` (a quaternion) its mirror image takes (see
    :func:`mirror`), for one motion or for clips of one skeleton together (their rotations
    pooled: the same frames for all, so their mirror images share one convention; the mean of a
    single clip doing something one-sided, such as waving one hand, can pick another twist).

    Any frame gives the exactly mirrored positions; the one chosen keeps the skeleton's
    conventions. Among the 24 rotations of the cube (the frames that map the joint's axes onto
    axes), those that keep its bones (the skeleton's offsets of its children and its end sites)
    within :data:`BONE_TOLERANCE`, the one nearest the
    frame that maps the partner's mean rotation onto the joint's own (``R_j = mean_p^-1 R_parent
    mean_j``, parents first); the plain reflection's (the half turn about x) unless another fits
    by :data:`PLAIN_MARGIN_RAD` better (the world's frame, above the root, being the half turn
    about x). Bones are the skeleton's offsets (not animated translations: those of the root's
    children are where the body is, which a mirror image moves). A skeleton
    whose joint frames line up with the world at rest (a T-pose BVH) keeps the plain reflection
    everywhere; Bandai-Namco's limbs (bones along +x on the left, -x on the right) take the
    identity, its spine a half turn about z and its hips one about y."""
    clips = [motions] if isinstance(motions, Motion) else list(motions)
    if not clips:
        raise MotionError("no motion to mirror")
    sk = clips[0].skeleton
    partner, _ = mirror_map(sk.names)
    bones = sk.offsets
    means = _mean_rotations(clips)
    frames = np.zeros((sk.num_joints, 4))
    for j in range(sk.num_joints):  # parents come before their children (Skeleton checks it)
        par, p = int(sk.parents[j]), int(partner[j])
        above = _HALF_X if par < 0 else frames[par]
        estimate = rot.multiply(rot.conjugate(means[p]), rot.multiply(above, means[j]))
        kids = np.flatnonzero(sk.parents == j)
        mine, theirs = [bones[kids]], [bones[partner[kids]]]
        es, es_p = np.flatnonzero(sk.end_site_parents == j), np.flatnonzero(sk.end_site_parents == p)
        if es.size and es.size == es_p.size:
            mine.append(sk.end_site_offsets[es])
            theirs.append(sk.end_site_offsets[es_p])
        own, other = np.concatenate(mine), np.concatenate(theirs)
        size = float(np.linalg.norm(own, axis=-1).sum())
        errors = np.array([float(np.linalg.norm(_image_of(c, other) - own, axis=-1).sum()) for c in _CUBE])
        keep = errors <= errors.min() + BONE_TOLERANCE * size
        angles = np.where(keep, _angles(_CUBE, estimate), np.inf)
        best = int(np.argmin(angles))
        if keep[0] and angles[0] <= angles[best] + PLAIN_MARGIN_RAD:
            best = 0
        frames[j] = _CUBE[best]
    return frames


def mirror(motion: Motion, frames: npt.NDArray[np.float64] | None = None) -> Motion:
    """The motion reflected across the YZ plane (x -> -x), left and right joints exchanged.

    Global positions satisfy ``mirror(m).global_positions()[:, j] == reflect(m.global_positions()
    [:, partner[j]])`` exactly, including for asymmetric skeletons (offsets are mirrored too).

    Frames. Joint ``j`` of the image (partner ``p``) takes the global rotation ``M G_p (-R_j)``
    (``M`` the world's reflection, ``R_j`` a rotation of the joint's own frame,
    :func:`joint_frames`): its local rotation is ``R_parent^-1 L_p R_j`` (the root's
    ``R_world^-1 L_0 R_0``, ``R_world`` the half turn about x), and its children's offsets and
    translations and its end sites are the partner's ``v`` as ``-R_j^-1 v``. Every choice of
    ``R_j`` gives the same positions; the plain reflection (``R_j`` the half turn about x: ``M L M``
    and ``M v``) suits skeletons whose frames line up with the world at rest. On a skeleton whose
    bones run along a local axis (Bandai-Namco's along x) it reverses every bone and turns every
    joint's frame half way round: a clip and a mirror image then have the same poses but other
    rotations, and a cut between them (a graph database with ``mirror``) blended local
    rotations across 150-180 degree jumps. The frames chosen keep the skeleton's conventions:
    ``frames`` ``(J, 4)`` (:func:`joint_frames` of the clips mirrored together, so that their
    images share one convention), or the motion's own :func:`joint_frames`.
    """
    sk = motion.skeleton
    partner, _ = mirror_map(sk.names)
    # the mirror of a joint's parent must be its mirror's parent
    if partner[0] != 0 or not np.array_equal(sk.parents[partner[1:]], partner[sk.parents[1:]]):
        raise MotionError("left/right joint names do not form a symmetric hierarchy; cannot mirror")
    if frames is None:
        frames = joint_frames(motion)
    elif np.shape(frames) != (sk.num_joints, 4):
        raise MotionError(f"frames must be (J, 4) = ({sk.num_joints}, 4), got {np.shape(frames)}")
    above = np.concatenate((_HALF_X[None], frames[sk.parents[1:]]))  # (J, 4) each parent's frame
    offsets = np.array(sk.offsets[partner], dtype=np.float64, copy=True)
    for j in range(sk.num_joints):
        offsets[j] = _image_of(above[j], offsets[j])
    es_parents = partner[sk.end_site_parents]
    es_offsets = np.array(sk.end_site_offsets, dtype=np.float64, copy=True)
    for e in range(es_offsets.shape[0]):
        es_offsets[e] = _image_of(frames[es_parents[e]], es_offsets[e])
    new_sk = Skeleton(sk.names, sk.parents, offsets, sk.channels, es_parents, es_offsets)
    translated = sk.translated_joints
    jt = motion.joint_translations
    if translated.size:
        slot = {int(j): k for k, j in enumerate(translated)}
        order = np.array([slot[int(partner[j])] for j in translated], dtype=np.intp)
        jt = np.array(jt[:, order], dtype=np.float64, copy=True)
        for k, j in enumerate(translated):
            jt[:, k] = _image_of(above[j], jt[:, k])
    q = np.asarray(motion.rotations, dtype=np.float64)[:, partner]
    if all(np.array_equal(f, _HALF_X) for f in frames):
        rotations = reflect_quaternions(q)  # the plain reflection everywhere
    else:
        rotations = rot.multiply(rot.multiply(rot.conjugate(above)[None], q), frames[None])
    return replace(
        motion,
        skeleton=new_sk,
        root_positions=reflect_vectors(motion.root_positions),
        rotations=rotations,
        joint_translations=jt,
    )
