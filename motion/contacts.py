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


# Foot plants, in body heights and seconds (so that a plant is one event at any frame rate)
PLANT_ENTER = (0.05, 0.35)
"""A plant starts where a foot is within 5 % of the body height of its floor and moves slower than
0.35 body heights per second horizontally (the quality report's contact thresholds)..."""
PLANT_STAY = (0.075, 0.6)
"""... and lasts while it stays within 7.5 % and under 0.6 body heights per second (hysteresis)."""
PLANT_SPEED_WINDOW_S = 0.1
"""Foot speed: the displacement over this span (centred), not frame to frame (mocap jitter)."""
PLANT_GAP_S = 0.12
"""Lifts shorter than this join the plants on either side."""
PLANT_MIN_S = 0.1
"""Plants shorter than this are dropped."""


def foot_groups(skeleton: Skeleton) -> list[tuple[int, ...]]:
    """The feet of a skeleton, one group of joints per foot (its ankle first, then its toe): by
    the roles of a naming convention both feet match (:func:`motion.retarget.names.detect_roles`:
    Unreal's ``foot_l`` and ``ball_l``, Mixamo's ``LeftFoot`` and ``LeftToeBase``), else the
    joints :func:`foot_joints` finds by name, grouped by side. Empty without feet."""
    from .retarget.names import detect_roles  # local: the retarget package imports this module

    roles = detect_roles(skeleton).joints
    if "LeftFoot" in roles and "RightFoot" in roles:
        return [
            tuple(roles[side + part] for part in ("Foot", "Toes") if side + part in roles)
            for side in ("Left", "Right")
        ]
    try:
        joints = foot_joints(skeleton)
    except MotionError:
        return []
    _, side = mirror_map(skeleton.names)
    toe = [bool(re.search("toe", skeleton.names[j], re.IGNORECASE)) for j in joints.tolist()]
    groups: list[tuple[int, ...]] = []
    for s in (1, -1, 0):
        members = [(t, int(j)) for j, t in zip(joints.tolist(), toe, strict=True) if side[j] == s]
        if s == 0:  # unpaired foot joints stand alone
            groups += [(j,) for _, j in members]
        elif members:
            groups.append(tuple(j for _, j in sorted(members)))
    return groups


def _plant_flags(
    positions: Array, fps: float, height: float, height_tol: float, speed_tol: float
) -> npt.NDArray[np.bool_]:
    """``(F, K)`` whether each foot joint (``positions (F, K, 3)``) is low and slow, in body
    heights (``height``, the positions' units)."""
    floor = np.percentile(positions[:, :, 1], 5, axis=0)
    low = positions[:, :, 1] - floor < height_tol * height
    f = positions.shape[0]
    half = max(1, int(round(PLANT_SPEED_WINDOW_S * fps / 2)))
    i = np.arange(f)
    a, b = np.clip(i - half, 0, f - 1), np.clip(i + half, 0, f - 1)
    span = np.maximum(b - a, 1) / fps
    speed = np.linalg.norm(positions[b][:, :, [0, 2]] - positions[a][:, :, [0, 2]], axis=-1) / span[:, None]
    return np.asarray(low & (speed < speed_tol * height))


def bool_runs(flags: npt.NDArray[np.bool_]) -> list[tuple[int, int]]:
    """``[(start, end), ...]`` frame runs of True in ``flags (F,)`` (end exclusive)."""
    x = np.concatenate(([0], np.asarray(flags).astype(np.int8), [0]))
    edges = np.flatnonzero(np.diff(x))
    return [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2], strict=True)]


def _debounced(
    stay: npt.NDArray[np.bool_], enter: npt.NDArray[np.bool_], fps: float
) -> list[tuple[int, int]]:
    """Runs of ``stay (F, K)`` (any of the K columns) that contain an ``enter`` frame of the same
    column, lifts shorter than :data:`PLANT_GAP_S` bridged and runs shorter than
    :data:`PLANT_MIN_S` dropped."""
    runs: list[tuple[int, int]] = []
    for k in range(stay.shape[1]):
        runs += [(a, b) for a, b in bool_runs(stay[:, k]) if enter[a:b, k].any()]
    runs.sort()
    joined: list[tuple[int, int]] = []
    for a, b in runs:
        if joined and (a - joined[-1][1]) / fps < PLANT_GAP_S:
            joined[-1] = (joined[-1][0], max(b, joined[-1][1]))
        else:
            joined.append((a, b))
    return [(a, b) for a, b in joined if (b - a) / fps >= PLANT_MIN_S - 1e-9]


def _plant_tests(
    motion: Motion, joints: npt.NDArray[np.intp], pos: Array
) -> tuple[npt.NDArray[np.bool_], npt.NDArray[np.bool_]] | None:
    """``(enter, stay)`` flags ``(F, K)`` of ``joints`` (None for a motion too short or flat)."""
    height = standing_height(pos)
    if motion.num_frames < 2 or height <= 0:
        return None
    feet = pos[:, joints]
    return (
        _plant_flags(feet, motion.fps, height, *PLANT_ENTER),
        _plant_flags(feet, motion.fps, height, *PLANT_STAY),
    )


def foot_plants(
    motion: Motion, groups: list[tuple[int, ...]] | None = None, *, positions: Array | None = None
) -> list[tuple[int, int, int]]:
    """The plants of each foot: ``(group index, start frame, end frame exclusive)``, one per plant
    whichever of the foot's joints (ankle, toe) touches, at any frame rate.

    A joint is planted where it meets :data:`PLANT_ENTER` and stays so while it meets
    :data:`PLANT_STAY` (hysteresis), speeds measured over :data:`PLANT_SPEED_WINDOW_S`; a foot is
    planted while any of its joints is (a heel strike, the flat foot and the push-off on the toe
    are one plant); lifts shorter than :data:`PLANT_GAP_S` are bridged and plants shorter than
    :data:`PLANT_MIN_S` dropped. ``groups``: the feet (:func:`foot_groups` by default);
    ``positions``: :meth:`Motion.global_positions` when the caller has them."""
    feet = foot_groups(motion.skeleton) if groups is None else groups
    if not feet:
        return []
    pos = motion.global_positions() if positions is None else positions
    joints = np.array([j for g in feet for j in g], dtype=np.intp)
    tests = _plant_tests(motion, joints, pos)
    if tests is None:
        return []
    enter, stay = tests
    out: list[tuple[int, int, int]] = []
    col = 0
    for g, group in enumerate(feet):
        cols = slice(col, col + len(group))
        col += len(group)
        out += [(g, a, b) for a, b in _debounced(stay[:, cols], enter[:, cols], motion.fps)]
    return out
