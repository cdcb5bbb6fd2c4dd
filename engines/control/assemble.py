"""Post-processing (Hsu et al. 2004, Sec. 5): the chosen target segments on the full skeleton.

Each segment is copied from its target clip, uniformly stretched to its duration, moved by its
alignment (rotation about +Y and floor translation, or the full 3-D rigid transform), and the
pieces are concatenated at the control's frame rate; the jumps at the boundaries are spread by
:func:`motion.smoothing.smooth_cuts`, and the instances' foot contacts and handhold flags are
carried to the output frames (by provenance).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
import numpy.typing as npt

from motion import Motion
from motion import rotations as rot
from motion.compiled import sample_into
from motion.ground import body_root
from motion.smoothing import smooth_cuts

from .build import ControlDatabase
from .dp import Timed

Array = npt.NDArray[np.float64]


@dataclass(slots=True)
class Assembled:
    """The output motion (metres, the control's rate and length) and what each frame came from."""

    motion: Motion
    clips: list[str]
    source_frames: npt.NDArray[np.float64]  # (F,) fractional frames of the target clips (database rate)
    global_frames: npt.NDArray[np.intp]  # (F,) nearest frame in the database's concatenated arrays
    segment_of_frame: npt.NDArray[np.intp]  # (F,)
    cuts: list[int]


def body_rooted(motion: Motion) -> tuple[Motion, int]:
    """The motion and the joint that carries the body (moved rigidly when a segment is placed).

    Usually joint 0. Skeletons whose joint 0 is a static origin with the body as its animated child
    (Bandai-Namco's ``joint_Root`` -> ``Hips``) are rewritten with joint 0 fixed at the origin and the
    body's world position and rotation on the body joint, so that placing pieces and smoothing the cuts
    between them moves the body, not a point metres away from it."""
    sk = motion.skeleton
    b = body_root(sk)
    if b == 0 or int(sk.parents[b]) != 0 or b not in sk.translated_joints:
        return motion, 0
    if any(int(sk.parents[j]) == 0 and j != b for j in range(1, sk.num_joints)):
        return motion, 0
    pos, grot = motion.fk()
    q = motion.rotations.copy()
    q[:, 0] = rot.identity((motion.num_frames,))
    q[:, b] = grot[:, b]
    jt = motion.joint_translations.copy()
    jt[:, int(np.flatnonzero(sk.translated_joints == b)[0])] = pos[:, b]
    root = np.zeros_like(motion.root_positions)
    return replace(motion, root_positions=root, rotations=q, joint_translations=jt), b


def assemble(
    db: ControlDatabase,
    clip_motion: Callable[[str], tuple[Motion, int]],
    instances: npt.NDArray[np.intp],
    timed: Timed,
    n_out: int,
    fps_out: float,
    smoothing_s: float,
) -> Assembled:
    """The target motion for a re-timed solution.

    Parameters
    ----------
    clip_motion:
        The target clip of a name, at the database rate (see :func:`body_rooted`).
    instances:
        ``(N, 3)`` the database's ``[pair, start, length]`` rows, indexed by ``timed.instances``.
    timed:
        Boundaries at the database rate (frames of the input resampled to it).
    n_out, fps_out:
        Frame count and rate of the control (the output matches them).
    smoothing_s:
        Half-width of the boundary smoothing in seconds (0 = none).
    """
    rate = db.fps
    u = np.arange(n_out) * (rate / fps_out)  # output frames in database-rate frames
    seg = np.clip(np.searchsorted(timed.bounds, u, side="right") - 1, 0, timed.instances.size - 1)
    b0, b1 = timed.bounds[seg], timed.bounds[seg + 1]
    alpha = np.clip((u - b0) / np.maximum(b1 - b0, 1), 0.0, 1.0)
    rows = instances[timed.instances[seg]]
    src = rows[:, 1] + alpha * rows[:, 2]
    pairs = rows[:, 0]
    first_clip = db.pairs[int(pairs[0])][1]
    base, carrier = clip_motion(first_clip)
    k_tr = int(np.flatnonzero(base.skeleton.translated_joints == carrier)[0]) if carrier else -1
    root = np.empty((n_out, 3))
    q = np.empty((n_out, base.num_joints, 4))
    jt = np.empty((n_out, *base.joint_translations.shape[1:]))
    # every piece of one clip is sampled at once (the pieces of a clip differ only in the frames)
    for pair in np.unique(pairs):
        idx = np.flatnonzero(pairs == pair)
        sample_into(clip_motion(db.pairs[int(pair)][1])[0], src[idx], idx, root, q, jt)
    # each frame moved by its segment's alignment
    p = jt[:, k_tr] if carrier else root
    if timed.rot is not None and timed.trans is not None:  # full 3-D rigid alignment
        moved = np.empty_like(p)
        for i in np.unique(seg):
            idx = np.flatnonzero(seg == i)
            moved[idx] = p[idx] @ timed.rot[i].T + timed.trans[i]
        turn = rot.from_matrix(timed.rot)[seg]
    else:
        c, s = timed.cos[seg], timed.sin[seg]
        moved = np.stack(
            (c * p[:, 0] + s * p[:, 2] + timed.tx[seg], p[:, 1], -s * p[:, 0] + c * p[:, 2] + timed.tz[seg]),
            -1,
        )
        turn = rot.from_yaw(np.arctan2(timed.sin, timed.cos))[seg]
    if carrier:
        jt[:, k_tr] = moved
    else:
        root = moved
    q[:, carrier] = rot.multiply(turn, q[:, carrier])
    names = np.array([target for _, target in db.pairs], dtype=object)
    clips: list[str] = names[pairs].tolist()
    motion = replace(
        base, root_positions=root, rotations=q, joint_translations=jt, fps=float(fps_out), name="control"
    )
    cuts = [int(c) for c in np.flatnonzero(np.diff(seg) != 0) + 1 if 1 <= c <= n_out - 1]
    window = int(round(smoothing_s * fps_out))
    if cuts and window >= 1:
        motion = smooth_cuts(motion, cuts, window)
    gidx = db.offsets[pairs] + np.clip(np.round(src).astype(np.intp), 0, None)
    gidx = np.minimum(gidx, db.offsets[pairs + 1] - 1)
    return Assembled(motion, clips, src, gidx, seg, cuts)
