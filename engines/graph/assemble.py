"""Assembly of the final motion from a path's pieces (Arikan & Forsyth 2002, Sec. 4.2.3).

1. **Place.** Each piece's frames (full skeleton, from the library) are moved by the piece's
   floor transform (:class:`~engines.graph.paths.Placement`: a rotation about +Y and a floor
   translation), so it continues where the previous piece ended.
2. **Smooth.** The discontinuities at the cuts are spread over ``+-smoothing_frames`` frames with
   the paper's displacement blend (:func:`motion.smoothing.smooth_cuts`).
3. **Meet the body constraints.** The body's remaining error at each body constraint (position
   and, when given, heading), measured on the smoothed motion, is distributed linearly over the
   frames since the previous body constraint; before the first one and after the last one the
   correction is rigid. The heading correction turns the path with the body (each frame's step is
   rotated by the correction angle of that frame), the position correction is a linear ramp; both
   are applied as one per-frame floor transform, so the constraints are met to numerical
   precision.
4. **Clean the feet.** Smoothing and the body correction make planted feet slide; the source
   clips' foot contacts at the provenance frames (:func:`motion.contacts.detect_contacts` on each
   clip, cached) are propagated to the output, and :func:`motion.footskate.remove_foot_skate`
   pins each contact run with leg IK (contacts stored by the build, see
   :class:`~engines.graph.model.FootContacts`). Only leg joint rotations change: the root and the hips
   (thighs), hence the body constraints, are untouched. Around each joint constraint on a leg
   joint, that leg's contacts are dropped (``blend`` frames either side) so the constrained joint
   keeps its assembled position exactly.

The body (the "torso" of the paper) is that of :func:`motion.ground.ground_frames` (the hips'
floor projection, facing from the thighs), as in the root tracks. For skeletons whose joint 0 is a
fixed reference that never moves (e.g. Bandai-Namco's ``joint_Root`` at the origin, with the
motion carried by the translated ``Hips``), the floor transforms are applied to joint 0's
children instead of joint 0, so smoothing never blends two differently placed reference joints.
"""

from __future__ import annotations

import threading
from dataclasses import replace
from typing import Any

import numpy as np

from motion import Motion
from motion.contacts import foot_joints
from motion.errors import MotionError
from motion.footskate import leg_chains, remove_foot_skate
from motion.ground import apply_floor_transform, ground_frames, static_reference_root
from motion.smoothing import smooth_cuts

from ..library import MotionLibrary
from .model import FloatArray, FootContacts, IntArray, RootTracks
from .paths import BoolArray, Pieces, Placement, rotate2, wrap_angle
from .score import Problem, compile_problem
from .tracks import foot_contacts


def body_frames(motion: Motion, positions: FloatArray | None = None) -> tuple[FloatArray, FloatArray]:
    """Per frame, the body's floor position ``(F, 2)`` metres and heading ``(F,)`` radians
    (:func:`motion.ground.ground_frames`: the hips' floor projection, facing from the thighs)."""
    xz, yaw = ground_frames(motion, positions)
    return xz * motion.metres_per_unit, yaw


def _concatenate(library: MotionLibrary, pieces: Pieces) -> Motion:
    """The pieces' frames end to end (the skeleton of the clip that gives the most frames)."""
    counts = pieces.count
    main = library.motions[int(pieces.clip[int(np.argmax(counts))])]
    spans = [
        (library.motions[int(c)], slice(int(a), int(b) + 1))
        for c, a, b in zip(pieces.clip, pieces.first, pieces.last, strict=True)
    ]
    return replace(
        main,
        root_positions=np.concatenate([m.root_positions[s] for m, s in spans]),
        rotations=np.concatenate([m.rotations[s] for m, s in spans]),
        joint_translations=np.concatenate([m.joint_translations[s] for m, s in spans]),
        name="graph",
    )


def _correction(
    body_xz: FloatArray, body_yaw: FloatArray, problem: Problem
) -> tuple[FloatArray, FloatArray] | None:
    """Per-frame floor transform ``theta (F,)``, ``shift (F, 2)`` meeting the body constraints."""
    n = body_xz.shape[0]
    targets = [b for b in problem.bodies if b.frame < n]
    if not targets:
        return None
    f = np.arange(n)
    kt = np.array([b.frame for b in targets if b.heading is not None], dtype=np.float64)
    ka = np.array(
        [float(wrap_angle(b.heading - body_yaw[b.frame])) for b in targets if b.heading is not None]
    )
    alpha = np.interp(f, kt, ka) if kt.size else np.zeros(n)
    steps = np.zeros((n, 2))
    steps[1:] = rotate2(alpha[1:], np.diff(body_xz, axis=0))
    path = np.cumsum(steps, axis=0)
    t0 = targets[0].frame
    path += body_xz[t0] - path[t0]
    rt = np.array([b.frame for b in targets], dtype=np.float64)
    res = np.stack([b.xz - path[b.frame] for b in targets])
    ramp = np.stack((np.interp(f, rt, res[:, 0]), np.interp(f, rt, res[:, 1])), axis=-1)
    goal = path + ramp
    return alpha, goal - rotate2(alpha, body_xz)


FOOT_BLEND_S = 0.1
"""Seconds over which foot pins fade in and out (:func:`motion.footskate.remove_foot_skate`)."""

_CONTACTS: dict[int, tuple[MotionLibrary, FootContacts]] = {}
_CONTACTS_LOCK = threading.Lock()


def library_contacts(library: MotionLibrary) -> FootContacts:
    """:func:`engines.graph.tracks.foot_contacts` of a library, cached for the last few libraries
    (by identity), for callers that do not hold the database's stored contacts."""
    key = id(library)
    with _CONTACTS_LOCK:
        got = _CONTACTS.get(key)
        if got is not None and got[0] is library:
            return got[1]
    contacts = foot_contacts(library)
    with _CONTACTS_LOCK:
        _CONTACTS[key] = (library, contacts)
        while len(_CONTACTS) > 4:
            _CONTACTS.pop(next(iter(_CONTACTS)))
    return contacts


def propagated_contacts(
    contacts: FootContacts, tracks: RootTracks, clips: IntArray, frames: IntArray
) -> tuple[IntArray, BoolArray]:
    """Foot joints ``(K,)`` and contact flags ``(F, K)`` of output frames played from source
    ``clips``/``frames`` ``(F,)``: each source frame's own contacts."""
    return contacts.joints, contacts.flags[tracks.offsets[clips] + frames]


def clean_feet(
    motion: Motion, contacts: tuple[IntArray, BoolArray], problem: Problem, blend_s: float = FOOT_BLEND_S
) -> Motion:
    """:func:`motion.footskate.remove_foot_skate` with the given contacts, except around joint
    constraints on leg joints (see the module docstring); the motion unchanged when its legs
    cannot be found."""
    joints, flags = contacts
    if not flags.any():
        return motion
    blend = int(round(blend_s * motion.fps))
    try:
        if problem.joints:
            flags = flags.copy()
            parents = motion.skeleton.parents
            legs = leg_chains(motion, joints)
            for jt in problem.joints:
                chain = set()
                j = int(parents[jt.joint])
                while j >= 0:
                    chain.add(j)
                    j = int(parents[j])
                for leg in legs:
                    if leg.hip in chain:
                        cols = [s for s in (leg.ankle_slot, leg.toe_slot) if s >= 0]
                        flags[max(jt.frame - blend, 0) : jt.frame + blend + 1, cols] = False
        return remove_foot_skate(motion, (joints, flags), blend_s=blend_s)
    except MotionError:  # no hip-knee-ankle chains above the feet: nothing to pin
        return motion


def assemble(
    library: MotionLibrary,
    tracks: RootTracks,
    pieces: Pieces,
    placement: Placement,
    request: Any,
    problem: Problem | None = None,
    *,
    feet: bool = True,
    contacts: FootContacts | None = None,
) -> tuple[Motion, list[tuple[str, int]]]:
    """The motion a path plays, placed, smoothed and meeting its body constraints.

    Parameters
    ----------
    library, tracks:
        The database (clips in metres at one rate; root tracks of the same frames).
    pieces, placement:
        From :func:`engines.graph.score.evaluate` (``(P,)`` pieces and their floor transforms).
    request:
        The :class:`schemas.graph.GraphRequest` (smoothing window and body constraints).
    problem:
        The request already compiled (:func:`engines.graph.score.compile_problem`), to skip it.
    feet:
        Clean foot skate with the source clips' contacts (step 4 of the module docstring).
    contacts:
        The database's foot contacts (:class:`~engines.graph.model.FootContacts`); computed from
        the library (and cached) when not given.

    Returns
    -------
    motion:
        ``pieces.frames`` frames (the requested length unless the path is too short).
    provenance:
        Per output frame, ``(clip name, source frame)``.
    """
    if problem is None:
        problem = compile_problem(request, library, tracks)
    for c, a, b in zip(pieces.clip, pieces.first, pieces.last, strict=True):
        if not 0 <= a <= b < tracks.frames(int(c)):
            raise MotionError(f"piece {a}..{b} is outside clip {library.names[int(c)]!r}")
    static = static_reference_root(library.motions)
    motion = _concatenate(library, pieces)
    theta, shift = placement.per_frame()
    motion = apply_floor_transform(motion, theta, shift, static)
    cuts = [int(s) for s in pieces.start[1:] if 0 < s < motion.num_frames]
    window = int(getattr(request, "smoothing_frames", 0))
    if cuts and window >= 1:
        motion = smooth_cuts(motion, cuts, window)
    if problem.bodies:
        xz, yaw = body_frames(motion)
        corr = _correction(xz, yaw, problem)
        if corr is not None:
            motion = apply_floor_transform(motion, corr[0], corr[1], static)
    clips, frames = pieces.source()
    if feet and motion.num_frames > 1:
        if contacts is None:
            contacts = library_contacts(library)
        if contacts.joints.size:
            motion = clean_feet(motion, propagated_contacts(contacts, tracks, clips, frames), problem)
    provenance = [(library.names[int(c)], int(f)) for c, f in zip(clips, frames, strict=True)]
    return motion, provenance


def constraint_errors(
    motion: Motion, provenance: list[tuple[str, int]], problem: Problem, library: MotionLibrary
) -> dict[str, Any]:
    """Each constraint's error measured on an assembled motion: ``length`` (frames), ``body[i]``
    (``position_cm``, ``heading_deg``), ``joint[i]`` (``position_cm``, ``velocity_cm_s``),
    ``pose[i]`` (``frames`` off in the source clip, ``held``), ``label[i]`` (``frames`` wrong of
    ``window``), ``obstacle[i]`` (``frames`` with root or a foot inside, deepest ``depth_cm``)."""
    out: dict[str, Any] = {"length": {"frames": abs(motion.num_frames - problem.length)}}
    n = motion.num_frames
    pos = np.ascontiguousarray(motion.global_positions()) * motion.metres_per_unit
    xz, yaw = body_frames(motion, pos / motion.metres_per_unit)
    for b in problem.bodies:
        if b.frame >= n:
            out[b.name] = {"frame": b.frame, "position_cm": None, "missing": True}
            continue
        e: dict[str, Any] = {
            "frame": b.frame,
            "position_cm": round(float(np.linalg.norm(xz[b.frame] - b.xz)) * 100, 4),
        }
        if b.heading is not None:
            e["heading_deg"] = round(abs(float(np.degrees(wrap_angle(yaw[b.frame] - b.heading)))), 4)
        out[b.name] = e
    for j in problem.joints:
        if j.frame >= n:
            out[j.name] = {"frame": j.frame, "position_cm": None, "missing": True}
            continue
        e = {
            "frame": j.frame,
            "position_cm": round(float(np.linalg.norm(pos[j.frame, j.joint] - j.position)) * 100, 4),
        }
        if j.velocity is not None:
            a, b2 = max(j.frame - 1, 0), min(j.frame + 1, n - 1)
            v = (pos[b2, j.joint] - pos[a, j.joint]) * motion.fps / max(b2 - a, 1)
            e["velocity_cm_s"] = round(float(np.linalg.norm(v - j.velocity)) * 100, 4)
        out[j.name] = e
    index = {name: i for i, name in enumerate(library.names)}
    for p in problem.poses:
        if p.frame >= n:
            out[p.name] = {"frame": p.frame, "held": False, "frames": None}
            continue
        clip, src = provenance[p.frame]
        same = index[clip] == p.clip
        out[p.name] = {
            "frame": p.frame,
            "held": same and src == p.clip_frame,
            "frames": abs(src - p.clip_frame) if same else None,
        }
    starts = np.concatenate(([0], np.cumsum([m.num_frames for m in library.motions])))
    rows = np.array([starts[index[c]] + f for c, f in provenance], dtype=np.int64)
    for lb in problem.labels:
        t = np.arange(lb.start, min(lb.end, n))
        ok = lb.good[rows[t] + 1] - lb.good[rows[t]]
        wrong = int((lb.end - lb.start) - ok.sum())
        out[lb.name] = {"frames": wrong, "window": lb.end - lb.start}
    if problem.obstacles:
        try:
            feet = list(foot_joints(motion.skeleton))
        except MotionError:
            feet = []
        pts = np.concatenate((xz[:, None, :], pos[:, feet][:, :, [0, 2]]), axis=1)
        for ob in problem.obstacles:
            d = ob.depth(pts).max(axis=1)
            out[ob.name] = {
                "frames": int(np.count_nonzero(d > 0)),
                "depth_cm": round(float(d.max(initial=0.0)) * 100, 4),
            }
    return out
