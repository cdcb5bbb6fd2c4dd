"""Foot-contact detection: a foot is planted when it is low and nearly still."""

from __future__ import annotations

import re

import numpy as np
import numpy.typing as npt
from scipy.ndimage import binary_closing, binary_opening

from .errors import MotionError
from .mirror import mirror_map
from .motion import Motion
from .skeleton import Skeleton
from .units import standing_height

Array = npt.NDArray[np.float64]

_FOOT = re.compile(r"foot|toe|ankle", re.IGNORECASE)


def foot_joints(skeleton: Skeleton) -> npt.NDArray[np.intp]:
    """Indices of foot joints: per leg, the ankle/foot joint and the first toe joint below it.

    Joints are found by name (``foot``, ``toe``, ``ankle``); among several toe joints of one side
    (finger-like toes), only the shallowest one is kept. Raises :class:`MotionError` when none.
    """
    depth = skeleton.depth()
    _, side = mirror_map(skeleton.names)
    chosen: list[int] = []
    for s in (1, -1, 0):
        cands = [j for j in range(skeleton.num_joints) if side[j] == s and _FOOT.search(skeleton.names[j])]
        if not cands:
            continue
        feet = [j for j in cands if not re.search("toe", skeleton.names[j], re.IGNORECASE)]
        toes = [j for j in cands if re.search("toe", skeleton.names[j], re.IGNORECASE)]
        if feet:
            chosen.append(min(feet, key=lambda j: (depth[j], j)))
        if toes:
            chosen.append(min(toes, key=lambda j: (depth[j], j)))
    if not chosen:
        raise MotionError("no foot joints found by name (foot, toe, ankle); pass joint indices")
    return np.array(sorted(set(chosen)), dtype=np.intp)


def detect_contacts(
    motion: Motion,
    joints: npt.NDArray[np.intp] | None = None,
    *,
    positions: Array | None = None,
    height_tolerance: float = 0.05,
    speed_tolerance: float = 0.35,
    min_frames: int = 3,
) -> tuple[npt.NDArray[np.intp], npt.NDArray[np.bool_]]:
    """Frames where each foot joint is in contact with the ground.

    A joint is in contact when it is within ``height_tolerance`` body heights of its own lowest
    level in the clip (its 5th height percentile, so ankles and toes each get their own floor
    and a clip need not stand at y = 0) and moves slower than ``speed_tolerance`` body heights
    per second horizontally. Gaps and blips shorter than ``min_frames`` are closed/removed.

    Returns
    -------
    joints:
        ``(K,)`` the joints examined (default: :func:`foot_joints`).
    contacts:
        ``(F, K)`` booleans.
    """
    idx = foot_joints(motion.skeleton) if joints is None else np.asarray(joints, dtype=np.intp)
    pos = motion.global_positions() if positions is None else positions
    feet = pos[:, idx]
    height = standing_height(pos)
    if height <= 0:
        raise MotionError("cannot detect contacts: the motion has no vertical extent")
    floor = np.percentile(feet[:, :, 1], 5, axis=0)
    low = feet[:, :, 1] - floor < height_tolerance * height
    if motion.num_frames > 1:
        step = np.linalg.norm(np.diff(feet[:, :, [0, 2]], axis=0), axis=-1) * motion.fps
        speed = np.concatenate((step[:1], 0.5 * (step[1:] + step[:-1]), step[-1:]), axis=0)
    else:
        speed = np.zeros(low.shape)
    contact = low & (speed < speed_tolerance * height)
    if min_frames > 1 and motion.num_frames >= min_frames:
        structure = np.ones((min_frames, 1), dtype=bool)
        contact = binary_closing(contact, structure=structure, border_value=0) | contact
        contact = binary_opening(contact, structure=structure, border_value=0)
    return idx, np.asarray(contact, dtype=bool)
