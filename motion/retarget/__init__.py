"""Retargeting: a motion moved onto a character of other joint names, proportions, rest pose and
units (KPS03 §5 retargets its rhythmic motions to characters of other sizes).

:func:`retarget` is a pure function: ``retarget(motion, character)`` returns the character's own
skeleton (names, offsets, End Sites, channel layout and units exactly as given) moving like
``motion``. The steps, one module each:

* :mod:`~motion.retarget.names`: which source joint drives which character joint (naming
  presets, spine/neck chains by structure, an explicit name map);
* :mod:`~motion.retarget.transfer`: world-space bone directions carried through the two rest
  poses, and the root path scaled by leg length;
* :mod:`~motion.retarget.legik`: planted feet kept planted and above the floor by two-bone leg IK;
* :mod:`~motion.retarget.rootmotion`: the root motion where the target engine wants it (the
  character's root bone at the floor, its hips, or none);
* :mod:`~motion.retarget.character`: reading a character (BVH or glTF/GLB skin) and its rest pose.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ..errors import MotionError
from ..motion import Motion
from ..skinning import BoundMesh
from .grounding import FEET_MODES, ground_feet
from .legik import character_soles, settle, sole_floor
from .names import PRESETS, ROLES, Correspondence, correspond, detect_roles
from .rootmotion import ROOT_MOTION_MODES, apply_root_motion
from .transfer import Pose, hips_path, place_hips, transfer_rotations

__all__ = [
    "FEET_MODES",
    "PRESETS",
    "ROLES",
    "ROOT_MOTION_MODES",
    "Correspondence",
    "correspond",
    "detect_roles",
    "retarget",
]


def _check_finite(motion: Motion, what: str) -> None:
    for name, arr in (
        ("rotations", motion.rotations),
        ("root positions", motion.root_positions),
        ("joint translations", motion.joint_translations),
        ("offsets", motion.skeleton.offsets),
    ):
        if not np.all(np.isfinite(arr)):
            raise MotionError(f"the {what} has non-finite {name} (NaN or infinity)")


def retarget(
    motion: Motion,
    character: Motion,
    *,
    name_map: Mapping[str, str] | None = None,
    feet: str = "lock",
    root_motion: str | None = None,
    mesh: BoundMesh | None = None,
) -> Motion:
    """``motion`` played by ``character``.

    Parameters
    ----------
    motion:
        The source motion (any skeleton with hips, legs and feet; any units).
    character:
        The character: its skeleton and, in frame 0, its rest pose (see
        :func:`motion.retarget.character.load_character`).
    name_map:
        ``{source joint or role: character joint}``, added to the automatic correspondence.
    feet:
        ``"lock"`` (planted feet held in place, soles on the floor), ``"grounding"`` (soles on the
        floor only: planted soles touch it, none goes under it) or ``"free"`` (the transfer
        alone): :mod:`motion.retarget.grounding`.
    root_motion:
        Where the root motion goes (:mod:`motion.retarget.rootmotion`): ``"root"`` (the joint
        above the hips, on the floor, turning with the body), ``"hips"`` or ``"none"``; ``None``
        leaves it on the character's root joint, moving with the hips.
    mesh:
        The character's skinned mesh (:func:`motion.skinning.read_skinned_mesh`): its soles are
        what stands on the floor; without it, soles made from its bones
        (:mod:`motion.retarget.sole`).

    Returns
    -------
    A motion with ``character.skeleton``, ``character.units`` and ``motion``'s frame count and fps:
    limbs point as the source's do, the hips travel the source's path scaled by the ratio of leg
    heights. Joints with no source keep their rest rotation.

    Raises
    ------
    MotionError
        When a required joint (hips, legs, feet) has no counterpart, an input is not finite, or
        ``root_motion="root"`` is asked of a skeleton starting at its hips.
    """
    if feet not in FEET_MODES:
        raise MotionError(f"feet {feet!r}: use one of {', '.join(FEET_MODES)}")
    if root_motion is not None and root_motion not in ROOT_MOTION_MODES:
        raise MotionError(f"root motion {root_motion!r}: use one of {', '.join(ROOT_MOTION_MODES)}")
    _check_finite(motion, "motion")
    _check_finite(character, "character")
    corr = correspond(motion.skeleton, character.skeleton, name_map)
    src_pose = Pose.of(motion)
    local = transfer_rotations(motion, character, corr, src_pose)
    n = motion.num_frames
    rest = character.slice(0, 1)
    out = Motion(
        character.skeleton,
        np.repeat(rest.root_positions, n, axis=0),
        local,
        motion.fps,
        np.repeat(rest.joint_translations, n, axis=0),
        character.units,
        motion.name,
    )
    path, _ = hips_path(motion, character, corr, src_pose, out)
    out = place_hips(out, corr.target_roles["Hips"], path)
    if feet != "free" and n > 1:
        roles = corr.target_roles
        soles = character_soles(rest, roles, mesh)
        floor = sole_floor(out, soles, rest, roles)
        out = ground_feet(settle(out, roles, rest, soles, floor), soles, floor, mode=feet)
    if not np.all(np.isfinite(out.rotations)) or not np.all(np.isfinite(out.root_positions)):
        raise MotionError("retargeting produced non-finite values (degenerate bones in a skeleton?)")
    if root_motion is not None:
        out = apply_root_motion(out, rest, corr.target_roles, root_motion)
    return out
