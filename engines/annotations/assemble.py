"""Creating the motion of a frame sequence (Arikan, Forsyth & O'Brien 2003, Sec. 4) and its report.

The source frames are concatenated (the skeleton of the clip giving the most frames), every piece
is moved on the floor by its placement (:func:`engines.annotations.search.placements`; for
skeletons whose joint 0 is a fixed reference, such as Bandai-Namco's ``joint_Root``, its children
are moved instead, as in the graph engine), the cuts are smoothed with the displacement blend of
:func:`motion.smoothing.smooth_cuts`, and foot skate is removed (:mod:`motion.footskate`) when
that module is installed.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np
import numpy.typing as npt

from motion import Motion
from motion.footskate import remove_foot_skate
from motion.ground import apply_floor_transform, static_reference_root
from motion.metrics import cut_discontinuity
from motion.smoothing import smooth_cuts

from ..base import Arrays
from ..library import MotionLibrary
from .search import TRANSITION_MARGIN, Candidate, Database, Problem, cuts_of, end_pose, wrap

IntArray = npt.NDArray[np.intp]


FloatArray = npt.NDArray[np.float64]


class Frames:
    """The library's frames end to end (from the stored arrays), for quick concatenation."""

    def __init__(self, library: MotionLibrary, arrays: Arrays) -> None:
        self.library = library
        self.root = np.asarray(arrays["library.root_positions"], dtype=np.float64)
        self.rotations = np.asarray(arrays["library.rotations"], dtype=np.float64)
        self.translations = np.asarray(arrays["library.joint_translations"], dtype=np.float64)
        self.static = static_reference_root(library.motions)


def assemble(
    db: Database, frames: Frames, pb: Problem, cand: Candidate, smoothing: int, footskate: bool
) -> tuple[Motion, IntArray]:
    """The motion of ``cand.sigma`` placed, smoothed and cleaned; and its cut frames ``(X,)``."""
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
    if footskate:
        motion = remove_foot_skate(motion)
    return motion, cuts


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


def constraint_report(db: Database, pb: Problem, cand: Candidate, motion: Motion) -> dict[str, Any]:
    """Errors of the frame and end constraints, measured on the result."""
    out: dict[str, Any] = {"length": {"frames": abs(motion.num_frames - pb.n)}}
    for i, (t, g) in enumerate(pb.constraints):
        got = int(cand.sigma[t])
        same_clip = db.clip_of[got] == db.clip_of[g]
        out[f"frame[{i}]"] = {
            "frame": t,
            "met": bool(got == g),
            "frames_off": int(abs(got - g)) if same_clip else None,
        }
    if pb.end_xz is not None:
        exz, eyaw = end_pose(db, cand.sigma, cand.theta, cand.shift)
        e: dict[str, Any] = {"position_m": float(np.linalg.norm(exz - pb.end_xz))}
        if pb.end_yaw is not None:
            e["heading_deg"] = float(np.degrees(abs(float(wrap(eyaw - pb.end_yaw)))))
        out["end"] = e
    return out


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
