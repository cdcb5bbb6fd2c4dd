"""Left/right mirroring of motions, with left/right joints paired by name."""

from __future__ import annotations

import re
from dataclasses import replace
from functools import lru_cache

import numpy as np
import numpy.typing as npt

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


def mirror(motion: Motion) -> Motion:
    """The motion reflected across the YZ plane (x -> -x), left and right joints exchanged.

    Global positions satisfy ``mirror(m).global_positions()[:, j] == reflect(m.global_positions()
    [:, partner[j]])`` exactly, including for asymmetric skeletons (offsets are mirrored too).
    """
    sk = motion.skeleton
    partner, _ = mirror_map(sk.names)
    es_parents = partner[sk.end_site_parents]
    new_sk = Skeleton(
        sk.names,
        sk.parents,
        reflect_vectors(sk.offsets[partner]),
        sk.channels,
        es_parents,
        reflect_vectors(sk.end_site_offsets),
    )
    # the mirror of a joint's parent must be its mirror's parent
    if partner[0] != 0 or not np.array_equal(sk.parents[partner[1:]], partner[sk.parents[1:]]):
        raise MotionError("left/right joint names do not form a symmetric hierarchy; cannot mirror")
    translated = sk.translated_joints
    jt = motion.joint_translations
    if translated.size:
        slot = {int(j): k for k, j in enumerate(translated)}
        order = np.array([slot[int(partner[j])] for j in translated], dtype=np.intp)
        jt = reflect_vectors(jt[:, order])
    return replace(
        motion,
        skeleton=new_sk,
        root_positions=reflect_vectors(motion.root_positions),
        rotations=reflect_quaternions(motion.rotations[:, partner]),
        joint_translations=jt,
    )
