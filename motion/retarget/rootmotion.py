"""Where a retargeted character's root motion goes: the convention of the engine it is made for.

After :func:`motion.retarget.retarget` the character's own root joint carries the hips' path
(it is the joint that holds the translation). Game engines want the root motion in one place:

* ``"root"`` (Unreal Engine, Godot, Blender, glTF by default): the joint above the hips (Unreal's
  ``root``) stays on the floor at its rest height, under the hips, and turns with the body's
  heading (yaw only); the hips move relative to it. Needs a joint above the hips.
* ``"hips"`` (Unity Humanoid, which computes root motion from the body itself; characters whose
  skeleton starts at the hips, like Mixamo's): the root stays in its rest pose; the hips carry the
  whole path and turn.
* ``"none"`` (an in-place clip): the root stays in its rest pose and the body moves relative to it
  as in ``"root"``: it dances over the root, facing the root's rest heading.

The heading is the floor direction of ``left thigh - right thigh`` crossed with up (forward =
left x up), relative to the same direction in the character's rest pose; the floor path is the
hips' floor projection (minus their rest offset from the root, turned by the heading). Global
positions and rotations of every joint below the root are unchanged in ``"root"`` and ``"hips"``
modes; in ``"none"`` they are expressed relative to that moving floor frame. Only the root and the
child of the root on the way to the hips change; that child gets translation channels.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import numpy.typing as npt

from .. import rotations as rot
from ..errors import MotionError
from ..motion import Motion
from ..skeleton import Skeleton
from .transfer import floor_heading

Array = npt.NDArray[np.float64]

ROOT_MOTION_MODES = ("root", "hips", "none")
"""Where the root motion goes (``--root-motion``)."""

TARGET_ROOT_MOTION = {"unreal": "root", "godot": "root", "gltf": "root", "blender": "root", "unity": "hips"}
"""Each target's convention; ``"root"`` falls back to ``"hips"`` for a skeleton starting at its hips."""

_POSITIONS = ("Xposition", "Yposition", "Zposition")


def default_root_motion(target: str, hips: int) -> str:
    """The root-motion mode of ``target`` for a character whose hips are joint ``hips`` (a
    skeleton starting at its hips has no joint above them to carry it: ``"hips"``)."""
    mode = TARGET_ROOT_MOTION.get(target.lower(), "root")
    return "hips" if mode == "root" and hips == 0 else mode


def apply_root_motion(motion: Motion, rest: Motion, roles: dict[str, int], mode: str) -> Motion:
    """``motion`` (a retargeted character) with its root motion where ``mode`` says (module
    docstring).

    Parameters
    ----------
    motion:
        The character moving (any units); joint 0 is its root.
    rest:
        The character in its rest pose (frame 0), same skeleton.
    roles:
        Role -> joint index (``Hips``, ``LeftUpperLeg``, ``RightUpperLeg`` are used).
    mode:
        One of :data:`ROOT_MOTION_MODES`.

    Raises
    ------
    MotionError
        For an unknown mode, or ``"root"`` on a skeleton with no joint above its hips.
    """
    if mode not in ROOT_MOTION_MODES:
        raise MotionError(f"root motion {mode!r}: use one of {', '.join(ROOT_MOTION_MODES)}")
    sk = motion.skeleton
    hips = roles["Hips"]
    if hips == 0:
        if mode == "root":
            raise MotionError(
                f"the character's skeleton starts at its hips ({sk.names[0]!r}): no joint above them "
                "can carry the root motion; use root motion on the hips (--root-motion hips) or none"
            )
        if mode == "hips":
            return motion
    pos, grot = motion.fk()
    rpos, rrot = rest.fk()
    left, right = roles["LeftUpperLeg"], roles["RightUpperLeg"]
    turn = floor_heading(pos, left, right) - floor_heading(rpos, left, right)[0]
    yaw = rot.from_yaw(turn)  # (F, 4)
    # the floor frame: the root's rest transform, turned by the heading, moved under the hips
    offset = rpos[0, hips] - rpos[0, 0]
    offset[1] = 0.0
    frame_pos = pos[:, hips] - rot.rotate(yaw, np.broadcast_to(offset, pos[:, hips].shape))
    frame_pos[:, 1] = rpos[0, 0, 1]
    frame_rot = rot.multiply(yaw, np.broadcast_to(rrot[0, 0], yaw.shape))
    if hips == 0:  # "none": the hips taken into the floor frame, put back at the rest frame
        back = rot.multiply(rrot[0, 0], rot.inverse(frame_rot))
        new_pos = rpos[0, 0] + rot.rotate(back, pos[:, 0] - frame_pos)
        rotations = np.array(motion.rotations, copy=True)
        rotations[:, 0] = rot.multiply(back, grot[:, 0])
        return replace(motion, root_positions=new_pos, rotations=rotations)
    if mode == "root":
        root_pos, root_rot = frame_pos, frame_rot
    else:
        root_pos = np.broadcast_to(rpos[0, 0], frame_pos.shape).copy()
        root_rot = np.broadcast_to(rrot[0, 0], frame_rot.shape).copy()
    child = hips
    while int(sk.parents[child]) != 0:
        child = int(sk.parents[child])
    if mode == "none":  # the child's world transform relative to the moving frame, from the rest one
        world_rot = rot.multiply(root_rot, rot.multiply(rot.inverse(frame_rot), grot[:, child]))
        world_pos = root_pos + rot.rotate(
            root_rot, rot.rotate(rot.inverse(frame_rot), pos[:, child] - frame_pos)
        )
    else:
        world_rot, world_pos = grot[:, child], pos[:, child]
    inv_root = rot.inverse(root_rot)
    local_pos = rot.rotate(inv_root, world_pos - root_pos)
    local_rot = rot.multiply(inv_root, world_rot)
    # the root's own local transform: the skeleton's root is at the top
    rotations = np.array(motion.rotations, copy=True)
    rotations[:, 0] = root_rot
    rotations[:, child] = local_rot
    translations = motion.local_translations()
    translations[:, child] = local_pos
    channels = list(sk.channels)
    if not any(c.endswith("position") for c in channels[child]):
        channels[child] = (*_POSITIONS, *channels[child])
    new_sk = Skeleton(
        sk.names, sk.parents, sk.offsets, tuple(channels), sk.end_site_parents, sk.end_site_offsets
    )
    return Motion(
        new_sk,
        root_pos,
        rot.standardize(rot.normalize(rotations)),
        motion.fps,
        joint_translations=translations[:, new_sk.translated_joints],
        units=motion.units,
        name=motion.name,
    )
