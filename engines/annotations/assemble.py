"""Creating the motion of a frame sequence (Arikan, Forsyth & O'Brien 2003, Sec. 4) and its report.

The source frames are concatenated (the skeleton of the clip giving the most frames), every piece
is moved on the floor by its placement (:func:`engines.annotations.search.placements`; for
skeletons whose joint 0 is a fixed reference, such as Bandai-Namco's ``joint_Root``, its children
are moved instead, as in the graph engine), the cuts are smoothed with the displacement blend of
:func:`motion.smoothing.smooth_cuts`, the end constraint's remaining error (the search meets it
only as well as its cuts between pooled solutions allow, Sec. 3.4) is spread over the motion
within the database's physical limits (:func:`motion.floorfit.floor_correction`), and foot skate
is removed (:mod:`motion.footskate`).

:func:`quality_inputs` says what the quality report measures the result against: the length, the
start placement, the end constraint, each frame constraint (the clip frame's pose) and each
painted run of the timeline (honoured by the labels of the frames played there).
"""

from __future__ import annotations

import itertools
from dataclasses import replace
from typing import Any

import numpy as np
import numpy.typing as npt

from motion import Motion
from motion.contacts import detect_contacts
from motion.floorfit import CorrectionLimits, FloorGoal, floor_correction
from motion.footskate import remove_foot_skate
from motion.goals import BodyGoal, Goal, LabelGoal, LengthGoal, PoseGoal, body_pose
from motion.ground import apply_floor_transform, ground_frames, pin_reference_roots
from motion.metrics import cut_discontinuity
from motion.quality import QualityInputs
from motion.smoothing import smooth_cuts

from ..base import Arrays
from ..library import MotionLibrary
from .search import TRANSITION_MARGIN, Candidate, Database, Problem, cuts_of

IntArray = npt.NDArray[np.intp]


FloatArray = npt.NDArray[np.float64]


class Frames:
    """The library's frames end to end (from the stored arrays), for quick concatenation.

    ``static`` is the library's usual static reference root
    (:func:`motion.ground.pin_reference_roots`); the frames of the few clips whose joint 0 leaves
    it (four Bandai-Namco ``dataset-1`` clips move ``joint_Root`` with ``Hips``) are those clips
    pinned to it, the same global poses, so placing and smoothing pieces never moves joint 0."""

    def __init__(self, library: MotionLibrary, arrays: Arrays) -> None:
        self.library = library
        self.root = np.asarray(arrays["library.root_positions"], dtype=np.float64)
        self.rotations = np.asarray(arrays["library.rotations"], dtype=np.float64)
        self.translations = np.asarray(arrays["library.joint_translations"], dtype=np.float64)
        self.static, pinned = pin_reference_roots(library.motions)
        moved = [i for i, (a, b) in enumerate(zip(pinned, library.motions, strict=True)) if a is not b]
        if moved:  # copies: stored arrays may be read-only maps
            self.root, self.rotations = self.root.copy(), self.rotations.copy()
            self.translations = self.translations.copy()
            starts = np.concatenate(([0], np.cumsum([m.num_frames for m in library.motions])))
            for i in moved:
                rows = slice(int(starts[i]), int(starts[i + 1]))
                self.root[rows] = pinned[i].root_positions
                self.rotations[rows] = pinned[i].rotations
                self.translations[rows] = pinned[i].joint_translations


def assemble(
    db: Database,
    frames: Frames,
    pb: Problem,
    cand: Candidate,
    smoothing: int,
    footskate: bool,
    limits: CorrectionLimits | None = None,
    floor: dict[int, tuple[float, float]] | None = None,
    lock: bool = True,
) -> tuple[Motion, IntArray]:
    """The motion of ``cand.sigma`` placed, smoothed, corrected towards the end constraint
    (within ``limits``; ``None``: without limit) and cleaned (``footskate``; ``lock=False``: the
    planted feet's height only); and its cut frames ``(X,)``."""
    sigma = cand.sigma
    clips = db.clip_of[sigma]
    main = frames.library.motions[int(np.bincount(clips).argmax())]
    motion = replace(
        main,
        root_positions=frames.root[sigma],
        rotations=frames.rotations[sigma],
        joint_translations=frames.translations[sigma],
        name="annotations",
    )
    motion = apply_floor_transform(motion, cand.theta, cand.shift, frames.static)
    cuts = cuts_of(db, sigma)
    if cuts.size and smoothing >= 1:
        motion = smooth_cuts(motion, cuts, smoothing)
    if pb.end_xz is not None:
        xz, yaw = ground_frames(motion)
        goals = [
            FloorGoal(0, pb.start_xz, pb.start_yaw),
            FloorGoal(pb.n - 1, pb.end_xz, pb.end_yaw),
        ]
        corr = floor_correction(xz * motion.metres_per_unit, yaw, motion.fps, goals, limits)
        motion = apply_floor_transform(motion, corr.theta, corr.shift, frames.static)
    if footskate:
        motion = clean_feet(motion, floor, lock)
    return motion, cuts


def clean_feet(motion: Motion, floor: dict[int, tuple[float, float]] | None, lock: bool = True) -> Motion:
    """:func:`motion.footskate.remove_foot_skate` with contacts detected on the motion and, given
    the examples' foot heights ``floor`` (:meth:`engines.base.Engine.foot_floor`), no foot lower
    than theirs; ``lock=False`` pins the planted feet's height only (``grounding``)."""
    joints, flags = detect_contacts(motion)
    lowest = None
    if floor and all(int(j) in floor for j in joints):
        lowest = np.array([floor[int(j)][1] for j in joints]) / motion.metres_per_unit
    return remove_foot_skate(motion, (joints, flags), floor=lowest, horizontal=lock)


def _ranges(flags: npt.NDArray[np.bool_]) -> list[list[int]]:
    """``[[start, end), ...]`` runs of True."""
    x = np.concatenate(([0], flags.astype(np.int8), [0]))
    edges = np.flatnonzero(np.diff(x))
    return [[int(a), int(b)] for a, b in zip(edges[::2], edges[1::2], strict=True)]


def label_report(db: Database, pb: Problem, sigma: IntArray) -> tuple[dict[str, Any], dict[str, float]]:
    """Per-frame requested vs achieved labels (``annotations`` of the report) and match metrics.

    A frame *matches* when its source frame carries every label requested there (1) and none of
    those forbidden there (-1); ``label_match_steady`` leaves out frames within
    :data:`TRANSITION_MARGIN` of a change of the timeline."""
    achieved = db.labels[sigma]  # (n, L)
    req = pb.q  # (n, T)
    ach = achieved[:, pb.cols].astype(np.float64)
    bad = ((req > 0) & (ach < 0)) | ((req < 0) & (ach > 0))
    ok: npt.NDArray[np.bool_] = np.asarray(~bad.any(axis=1))
    change = np.zeros(pb.n, dtype=bool)
    if req.shape[1]:
        change[1:] = np.any(req[1:] != req[:-1], axis=1)
    near = np.zeros(pb.n, dtype=bool)
    for c in np.flatnonzero(change).tolist():
        near[max(0, c - TRANSITION_MARGIN) : c + TRANSITION_MARGIN] = True
    steady = ~near
    names = [db.vocab[int(c)] for c in pb.cols]
    annotations: dict[str, Any] = {
        "timeline_labels": names,
        "requested": {nm: [int(v) for v in req[:, i]] for i, nm in enumerate(names)},
        "achieved": {nm: [int(v) for v in ach[:, i]] for i, nm in enumerate(names)},
        "match": [bool(v) for v in ok],
        "achieved_ranges": {
            lab: _ranges(achieved[:, j] > 0) for j, lab in enumerate(db.vocab) if np.any(achieved[:, j] > 0)
        },
        "per_label": {
            nm: {
                "wanted_frames": int(np.sum(req[:, i] > 0)),
                "wanted_met": int(np.sum((req[:, i] > 0) & (ach[:, i] > 0))),
                "forbidden_frames": int(np.sum(req[:, i] < 0)),
                "forbidden_met": int(np.sum((req[:, i] < 0) & (ach[:, i] < 0))),
            }
            for i, nm in enumerate(names)
        },
    }
    metrics = {
        "label_match": float(ok.mean()),
        "label_match_steady": float(ok[steady].mean()) if steady.any() else float(ok.mean()),
    }
    return annotations, metrics


def quality_inputs(
    db: Database, frames: Frames, pb: Problem, sigma: IntArray, cuts: IntArray
) -> QualityInputs:
    """What the quality report measures the motion of ``sigma`` (database frames, ``(n,)``)
    against (module docstring). Timeline runs are the painted values (later entries over earlier
    ones): each run of 1 or -1 of one label is a ``label[i]`` goal, honoured where the frame
    played carries (or does not carry) the label, frames within :data:`TRANSITION_MARGIN` of the
    run's ends not counted."""
    goals: list[Goal] = [LengthGoal(pb.n), BodyGoal("start", 0, pb.start_xz, pb.start_yaw)]
    if pb.end_xz is not None:
        goals.append(BodyGoal("end", pb.n - 1, pb.end_xz, pb.end_yaw))
    for i, (t, g) in enumerate(pb.constraints):
        c = int(db.clip_of[g])
        src = frames.library.motions[c]
        k = int(g - db.clip_start[c])
        pose = body_pose(src.slice(k, k + 1).global_positions() * src.metres_per_unit, src.skeleton)[0]
        played = int(sigma[t]) if t < sigma.size else -1
        same = played >= 0 and int(db.clip_of[played]) == c
        extra = {"met": played == g, "frames_off": abs(played - g) if same else None}
        goals.append(PoseGoal(f"frame[{i}]", t, pose, extra=extra))
    achieved = db.labels[sigma][:, pb.cols] if pb.cols.size else np.zeros((sigma.size, 0))
    k = 0
    for col in range(pb.cols.size):
        values = pb.q[:, col]
        edges = np.flatnonzero(np.diff(np.concatenate(([0.0], values, [0.0]))))
        for a, b in itertools.pairwise(edges):
            v = int(values[a])
            if v == 0:
                continue
            got = achieved[a:b, col]
            honoured: npt.NDArray[np.bool_] = np.asarray(got > 0 if v > 0 else got <= 0)
            label = db.vocab[int(pb.cols[col])]
            goals.append(LabelGoal(f"label[{k}]", label, int(a), int(b), v, honoured, TRANSITION_MARGIN))
            k += 1
    return QualityInputs(goals=tuple(goals), joins=np.asarray(cuts, dtype=np.intp))


def discontinuity(motion: Motion, cuts: IntArray) -> dict[str, float]:
    """Mean and largest cut discontinuity of the final motion, metres
    (:func:`motion.metrics.cut_discontinuity`)."""
    inner = cuts[(cuts >= 2) & (cuts <= motion.num_frames - 2)]
    if inner.size == 0:
        return {"cuts": float(cuts.size), "cut_discontinuity_mean_m": 0.0, "cut_discontinuity_max_m": 0.0}
    d = cut_discontinuity(motion, inner)
    return {
        "cuts": float(cuts.size),
        "cut_discontinuity_mean_m": float(d.mean()),
        "cut_discontinuity_max_m": float(d.max()),
    }
