"""A character bound to a source skeleton frame by frame: the retargeting a viewer applies to motion
that arrives one frame at a time (a live session's frames, a clip it plays).

:func:`retarget` works on a whole motion: it plants feet over their contact frames, scales the hip
path by the median hip height over all frames and places the root motion. A stream has no whole
motion, so :func:`bind` measures, once per (source skeleton, character), what the retargeting's
own rotation transfer (:func:`~motion.retarget.transfer.transfer_rotations`) does at the source's
rest pose and keeps it as a :class:`Binding`:

* each driven character joint's source joint (the same correspondence, :func:`correspond`) and a
  constant world-rotation offset: ``character world rotation = source world rotation * offset``.
  At the rest pose this is exactly the transfer; in motion it is the transfer without its swing
  (the correction an aimed joint gets when its source bone spans several bent joints) and without
  the planted-foot orientation, which need the frames around;
* joints without a source keep their rest rotation relative to their parent;
* the hips follow the source's hips as :func:`~motion.retarget.transfer.hips_path` scales them:
  floor position times the hip-height ratio of the two rest poses, height above the source's
  standing ankle height times that ratio, plus the character's own ankle height.

:func:`apply_binding` applies a binding to a motion (what the page does in JavaScript,
``web/js/body.js``): per frame, in time linear in the joints. On a walk it stays within a few
centimetres of :func:`retarget` without foot planting (``tests/motion/retarget/test_binding.py``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from .. import rotations as rot
from ..errors import MotionError
from ..ground import body_root
from ..motion import Motion
from ..skeleton import Skeleton
from .names import correspond
from .transfer import (
    Pose,
    floor_height,
    hip_height_ratio,
    hips_path,
    leg_length,
    locals_from_globals,
    place_hips,
    planted_feet,
    transfer_rotations,
)

Array = npt.NDArray[np.float64]

__all__ = ["Binding", "apply_binding", "bind", "own_binding", "rest_motion"]


@dataclass(frozen=True, slots=True)
class Binding:
    """How a character follows a source skeleton frame by frame (module docstring).

    Attributes
    ----------
    source, target:
        The joint names of the source skeleton and of the character.
    driven:
        ``(D,)`` character joints that follow a source joint, parents before children.
    sources:
        ``(D,)`` the source joint each follows.
    offsets:
        ``(D, 4)`` world-rotation offsets (x, y, z, w): character world rotation = source world
        rotation * offset.
    rest_local:
        ``(J_character, 4)`` the character's rest local rotations (joints without a source keep
        theirs).
    hips, source_hips:
        The character's hips joint and the source's.
    scale:
        Character hip height over the source's (each in its own units).
    source_floor, target_floor:
        The source's standing ankle height (source units) and the character's (character units):
        a source hip height ``y`` becomes ``target_floor + scale * (y - source_floor)``.
    """

    source: tuple[str, ...]
    target: tuple[str, ...]
    driven: npt.NDArray[np.intp]
    sources: npt.NDArray[np.intp]
    offsets: Array
    rest_local: Array
    hips: int
    source_hips: int
    scale: float
    source_floor: float
    target_floor: float

    def to_json(self) -> dict[str, Any]:
        """The binding as the viewer reads it (names, not indices; quaternions rounded to 1e-7)."""
        return {
            "source": list(self.source),
            "target": list(self.target),
            "joints": [
                {"joint": self.target[int(t)], "source": self.source[int(s)], "offset": _q(self.offsets[k])}
                for k, (t, s) in enumerate(zip(self.driven, self.sources, strict=True))
            ],
            "hips": {
                "joint": self.target[self.hips],
                "source": self.source[self.source_hips],
                "scale": round(self.scale, 7),
                "source_floor": round(self.source_floor, 7),
                "target_floor": round(self.target_floor, 7),
            },
        }


def _q(q: Array) -> list[float]:
    return [round(float(x), 7) for x in q]


def rest_motion(skeleton: Skeleton, units: str = "m", name: str = "") -> Motion:
    """The zero-rotation pose of ``skeleton`` (its offsets) as a one-frame motion: a source's rest."""
    j = skeleton.num_joints
    return Motion(
        skeleton,
        skeleton.offsets[:1].copy(),
        np.tile(rot.IDENTITY, (1, j, 1)),
        30.0,
        np.zeros((1, skeleton.translated_joints.size, 3)),
        units,
        name,
    )


def _standing_ankle_height(pose: Motion, feet: list[int]) -> float:
    """The height of the ankles above the soles of ``pose`` (one frame): per foot, the ankle's
    height above the lowest point of the foot (its joints and End Sites below it); the lower foot."""
    sk = pose.skeleton
    pos, grot = pose.fk()
    ends = pose.end_site_positions(pos, grot)[0] if sk.end_site_parents.size else np.zeros((0, 3))
    heights = []
    for foot in feet:
        below = [foot]
        for k in range(foot + 1, sk.num_joints):
            if int(sk.parents[k]) in below:
                below.append(k)
        ys = [float(pos[0, k, 1]) for k in below]
        ys += [float(ends[e, 1]) for e in np.flatnonzero(np.isin(sk.end_site_parents, below))]
        heights.append(float(pos[0, foot, 1]) - min(ys))
    return min(heights)


def bind(
    source: Skeleton,
    character: Motion,
    *,
    example: Motion | None = None,
    name_map: Mapping[str, str] | None = None,
) -> Binding:
    """The binding of ``character`` (its skeleton, and its rest pose in frame 0, as
    :func:`~motion.retarget.character.load_character` reads it) to motion on ``source`` (module
    docstring), ``source`` in any units (the floor heights are in each skeleton's own).

    ``example``: frames of motion on ``source`` (the clip a viewer plays, a live session's first
    beats). With it, what :func:`retarget` measures on a whole motion is measured on them: the
    hip-height ratio and the source's floor (:func:`~motion.retarget.transfer.hips_path`) and the
    orientation of a planted foot (:func:`~motion.retarget.transfer.planted_feet`: a foot the
    example plants lands flat, as the character's own rest foot); without it, the rest poses'.

    Raises :class:`MotionError` when the skeletons do not correspond (a required joint missing on
    either side: hips, legs, feet), the example is on another skeleton, or a skeleton has legs of
    zero length."""
    if example is not None and not example.skeleton.same_structure(source):
        raise MotionError("the example frames are not on the source skeleton")
    src_rest = rest_motion(source)
    char_rest = character.slice(0, 1)
    corr = correspond(source, char_rest.skeleton, name_map)
    t0 = Pose.of(char_rest)
    local = transfer_rotations(src_rest, char_rest, corr, Pose.of(src_rest))
    _, g_target = _on(char_rest, local).fk()
    s_pos, g_source = src_rest.fk()
    driven = np.array(sorted(corr.pairs), dtype=np.intp)
    sources = np.array([corr.pairs[int(j)] for j in driven], dtype=np.intp)
    offsets = rot.multiply(rot.inverse(g_source[0, sources]), g_target[0, driven])
    sr, tr = corr.source_roles, corr.target_roles
    feet = [sr["LeftFoot"], sr["RightFoot"]]
    if example is None:
        t_pos = _on(char_rest, local).global_positions()
        chain = leg_length(t_pos[0], tr) / max(leg_length(s_pos[0], sr), 1e-300)
        if not (np.isfinite(chain) and chain > 0):
            raise MotionError("cannot scale the hips: a skeleton has legs of zero length")
        scale = hip_height_ratio(s_pos, t_pos, corr, chain)
        source_floor = _standing_ankle_height(src_rest, feet)
    else:
        sp = Pose.of(example)
        moving = _on(char_rest, transfer_rotations(example, char_rest, corr, sp), example.num_frames)
        _, scale = hips_path(example, char_rest, corr, sp, moving)
        source_floor = floor_height(sp.positions, feet)
        row = {int(j): k for k, j in enumerate(driven)}
        for j, planted in planted_feet(example, char_rest, corr, sp, t0).items():
            offsets[row[j]] = rot.multiply(rot.inverse(sp.rotations[0, corr.pairs[j]]), planted[0])
    t_rest = t0.positions[0]
    target_floor = float(t_rest[[tr["LeftFoot"], tr["RightFoot"]], 1].min())
    if t_rest[tr["Hips"], 1] - target_floor < 0.5 * leg_length(t_rest, tr):  # a rest pose not standing
        target_floor = scale * source_floor  # as hips_path: the source's floor, scaled
    return Binding(
        source=source.names,
        target=char_rest.skeleton.names,
        driven=driven,
        sources=sources,
        offsets=np.asarray(rot.standardize(rot.normalize(offsets))),
        rest_local=np.asarray(char_rest.rotations[0]),
        hips=tr["Hips"],
        source_hips=sr["Hips"],
        scale=float(scale),
        source_floor=float(source_floor),
        target_floor=target_floor,
    )


def own_binding(rest: Motion, character: Motion) -> Binding:
    """The binding of a character made on the source's own skeleton (Segue's mannequin): every
    joint follows itself, no retargeting. ``rest``: the source pose the character's mesh was made
    in (one frame); ``character``: the character as read from its file (its bind pose in frame 0,
    the same joint names). Offsets carry the bind pose's joint orientations (a file may store its
    joints turned or not), the hips follow the source's exactly."""
    sk, names = rest.skeleton, character.skeleton.names
    if sk.names != names:
        raise MotionError("the character is not on the source's skeleton (joint names differ)")
    _, g_rest = rest.slice(0, 1).fk()
    _, g_char = character.slice(0, 1).fk()
    joints = np.arange(sk.num_joints, dtype=np.intp)
    hips = body_root(sk)
    return Binding(
        source=sk.names,
        target=names,
        driven=joints,
        sources=joints,
        offsets=np.asarray(rot.standardize(rot.multiply(rot.inverse(g_rest[0]), g_char[0]))),
        rest_local=np.asarray(character.rotations[0]),
        hips=hips,
        source_hips=hips,
        scale=1.0,
        source_floor=0.0,
        target_floor=0.0,
    )


def _on(rest: Motion, local: Array, frames: int = 1) -> Motion:
    """``rest`` (one frame) with the local rotations ``local (F, J, 4)``, its root where it rests."""
    return Motion(
        rest.skeleton,
        np.repeat(rest.root_positions, frames, axis=0),
        local,
        rest.fps,
        np.repeat(rest.joint_translations, frames, axis=0),
        rest.units,
        rest.name,
    )


def apply_binding(binding: Binding, motion: Motion, character: Motion) -> Motion:
    """``character`` following ``motion`` by ``binding`` (made for ``motion``'s skeleton and
    ``character``), frame by frame: a motion of the character's skeleton and units with
    ``motion``'s frames and fps."""
    if motion.skeleton.names != binding.source or character.skeleton.names != binding.target:
        raise MotionError("the binding was made for other skeletons (joint names differ)")
    _, g_source = motion.fk()
    sk = character.skeleton
    n = motion.num_frames
    pairs = enumerate(zip(binding.driven, binding.sources, strict=True))
    desired = {int(j): rot.multiply(g_source[:, int(s)], binding.offsets[k]) for k, (j, s) in pairs}
    local = locals_from_globals(sk, desired, binding.rest_local, n)
    rest = character.slice(0, 1)
    out = Motion(
        sk,
        np.repeat(rest.root_positions, n, axis=0),
        rot.standardize(rot.normalize(local)),
        motion.fps,
        np.repeat(rest.joint_translations, n, axis=0),
        character.units,
        motion.name,
    )
    hips = motion.global_positions()[:, binding.source_hips]
    path = hips * binding.scale
    path[:, 1] = binding.target_floor + binding.scale * (hips[:, 1] - binding.source_floor)
    return place_hips(out, binding.hips, path)
