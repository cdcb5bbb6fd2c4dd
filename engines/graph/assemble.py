"""Assembly of the final motion from a path's pieces (Arikan & Forsyth 2002, Sec. 4.2.3).

1. **Place.** Each piece's frames (full skeleton, from the library) are moved by the piece's
   floor transform (:class:`~engines.graph.paths.Placement`: a rotation about +Y and a floor
   translation), so it continues where the previous piece ended.
2. **Smooth.** The discontinuities at the cuts are spread over ``+-smoothing_frames`` frames with
   the paper's displacement blend (:func:`motion.smoothing.smooth_cuts`).
3. **Meet the body constraints.** The body's remaining error at each body constraint (position
   and, when given, heading) and the floor part of each joint constraint's error, measured on the
   smoothed motion, are spread over the frames since the previous one, as evenly as the
   database's physical limits allow (:func:`motion.floorfit.floor_correction`: never faster or
   turning faster than the fastest example, at most 15 % more speed than the frame has plus
   5 cm/s); before the first one and after the last one the correction is rigid. The heading
   correction turns the path with the body, the position correction is a ramp; both are applied
   as one per-frame floor transform. What the limits do not allow stays as error, and the
   quality report says so (the paper spreads without limit, which can drag a body at any speed).
4. **Clean the feet.** Smoothing and the body correction make planted feet slide (and sink or
   float where a cut between clips of different hip heights is smoothed); the source clips' foot
   contacts at the provenance frames (:func:`motion.contacts.detect_contacts` on each clip,
   cached) are propagated to the output, and :func:`motion.footskate.remove_foot_skate` pins each
   contact run, at the feet's height in the source frames, with leg IK, and lifts any foot that
   would go lower than the examples' feet ever do (contacts stored by the build, see
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
from motion.errors import MotionError
from motion.floorfit import CorrectionLimits, FloorGoal, floor_correction
from motion.footskate import leg_chains, remove_foot_skate
from motion.goals import (
    BodyGoal,
    Goal,
    JointGoal,
    LabelGoal,
    LengthGoal,
    ObstacleGoal,
    PoseGoal,
    body_pose,
)
from motion.ground import (
    StaticRoot,
    apply_floor_transform,
    body_root,
    ground_frames,
    pin_reference_roots,
)
from motion.quality import QualityInputs
from motion.smoothing import smooth_cuts
from schemas.graph import GraphRequest

from ..library import MotionLibrary
from .model import FloatArray, FootContacts, IntArray, RootTracks
from .paths import BoolArray, Pieces, Placement
from .score import Problem, compile_problem
from .tracks import foot_contacts


def body_frames(motion: Motion, positions: FloatArray | None = None) -> tuple[FloatArray, FloatArray]:
    """Per frame, the body's floor position ``(F, 2)`` metres and heading ``(F,)`` radians
    (:func:`motion.ground.ground_frames`: the hips' floor projection, facing from the thighs)."""
    xz, yaw = ground_frames(motion, positions)
    return xz * motion.metres_per_unit, yaw


def _concatenate(motions: tuple[Motion, ...], pieces: Pieces) -> Motion:
    """The pieces' frames end to end (the skeleton of the clip that gives the most frames)."""
    counts = pieces.count
    main = motions[int(pieces.clip[int(np.argmax(counts))])]
    spans = [
        (motions[int(c)], slice(int(a), int(b) + 1))
        for c, a, b in zip(pieces.clip, pieces.first, pieces.last, strict=True)
    ]
    return replace(
        main,
        root_positions=np.concatenate([m.root_positions[s] for m, s in spans]),
        rotations=np.concatenate([m.rotations[s] for m, s in spans]),
        joint_translations=np.concatenate([m.joint_translations[s] for m, s in spans]),
        name="graph",
    )


def floor_goals(motion: Motion, positions: FloatArray, problem: Problem) -> list[FloorGoal]:
    """The floor goals of a motion's body and joint constraints (:mod:`motion.floorfit`): body
    constraints as they are, joint constraints as their floor part, aimed through the joint's
    offset from the body (``positions (F, J, 3)`` in the motion's units)."""
    n = motion.num_frames
    mpu = motion.metres_per_unit
    goals = [FloorGoal(b.frame, b.xz, b.heading) for b in problem.bodies if b.frame < n]
    body = positions[:, body_root(motion.skeleton)][:, [0, 2]] * mpu
    for j in problem.joints:
        if j.frame < n:
            offset = positions[j.frame, j.joint, [0, 2]] * mpu - body[j.frame]
            goals.append(FloorGoal(j.frame, j.position[[0, 2]], None, offset))
    return goals


FOOT_BLEND_S = 0.1
"""Seconds over which foot pins fade in and out (:func:`motion.footskate.remove_foot_skate`)."""

_CONTACTS: dict[int, tuple[MotionLibrary, FootContacts]] = {}
_CONTACTS_LOCK = threading.Lock()
_PINNED: dict[int, tuple[MotionLibrary, StaticRoot | None, tuple[Motion, ...]]] = {}


def pinned_clips(library: MotionLibrary) -> tuple[StaticRoot | None, tuple[Motion, ...]]:
    """The library's usual static reference root and its clips with every clip whose joint 0
    moves pinned to it (:func:`motion.ground.pin_reference_roots`); the clips as they are when
    there is none. Cached for the last few libraries (by identity)."""
    key = id(library)
    with _CONTACTS_LOCK:
        got = _PINNED.get(key)
        if got is not None and got[0] is library:
            return got[1], got[2]
    static, motions = pin_reference_roots(library.motions)
    with _CONTACTS_LOCK:
        _PINNED[key] = (library, static, motions)
        while len(_PINNED) > 4:
            _PINNED.pop(next(iter(_PINNED)))
    return static, motions


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
    motion: Motion,
    contacts: tuple[IntArray, BoolArray],
    problem: Problem,
    blend_s: float = FOOT_BLEND_S,
    heights: FloatArray | None = None,
    floor: FloatArray | None = None,
    lock: bool = True,
) -> Motion:
    """:func:`motion.footskate.remove_foot_skate` with the given contacts (and rest ``heights``
    ``(F, K)`` and lowest heights ``floor (K,)`` of the contact joints), except around joint
    constraints on leg joints (see the module docstring); the motion unchanged when its legs
    cannot be found. ``lock=False`` pins the planted feet's height only."""
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
        return remove_foot_skate(
            motion, (joints, flags), blend_s=blend_s, heights=heights, floor=floor, horizontal=lock
        )
    except MotionError:  # no hip-knee-ankle chains above the feet: nothing to pin
        return motion


def assemble(
    library: MotionLibrary,
    tracks: RootTracks,
    pieces: Pieces,
    placement: Placement,
    request: GraphRequest,
    problem: Problem | None = None,
    *,
    feet: bool = True,
    lock: bool = True,
    contacts: FootContacts | None = None,
    limits: CorrectionLimits | None = None,
    floor: dict[int, tuple[float, float]] | None = None,
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
    lock:
        Hold planted feet in place (the request's ``feet``: ``lock``); off, their height only
        (``grounding``: they rest at their planted height and never go under the floor).
    contacts:
        The database's foot contacts (:class:`~engines.graph.model.FootContacts`); computed from
        the library (and cached) when not given.
    limits:
        How much of the body constraints' error a frame may absorb (step 3); ``None`` spreads it
        without limit (the paper's rule).
    floor:
        Per foot joint, the examples' (planted, lowest) heights in metres
        (:meth:`engines.base.Engine.foot_floor`): no foot goes lower (step 4).

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
    # joint 0 held at its usual pose in every clip (a few clips of some sets move it too)
    static, motions = pinned_clips(library)
    motion = _concatenate(motions, pieces)
    theta, shift = placement.per_frame()
    motion = apply_floor_transform(motion, theta, shift, static)
    placed = motion  # the source frames as they are, before the cuts are smoothed
    cuts = [int(s) for s in pieces.start[1:] if 0 < s < motion.num_frames]
    window = int(getattr(request, "smoothing_frames", 0))
    if cuts and window >= 1:
        motion = smooth_cuts(motion, cuts, window)
    if problem.bodies or problem.joints:
        positions = motion.global_positions()
        goals = floor_goals(motion, positions, problem)
        if goals:
            xz, yaw = body_frames(motion, positions)
            corr = floor_correction(xz, yaw, motion.fps, goals, limits)
            motion = apply_floor_transform(motion, corr.theta, corr.shift, static)
    clips, frames = pieces.source()
    if feet and motion.num_frames > 1:
        if contacts is None:
            contacts = library_contacts(library)
        if contacts.joints.size:
            joints, flags = propagated_contacts(contacts, tracks, clips, frames)
            # planted feet rest at their height in the source frames (smoothing a cut between clips
            # of different hip heights lowers or raises them)
            rest = placed.global_positions()[:, joints, 1]
            lowest = None
            if floor and all(int(j) in floor for j in joints):
                lowest = np.array([floor[int(j)][1] for j in joints]) / motion.metres_per_unit
            motion = clean_feet(motion, (joints, flags), problem, heights=rest, floor=lowest, lock=lock)
    provenance = [(library.names[int(c)], int(f)) for c, f in zip(clips, frames, strict=True)]
    return motion, provenance


def quality_inputs(
    motion: Motion,
    provenance: list[tuple[str, int]],
    cuts: IntArray,
    problem: Problem,
    library: MotionLibrary,
) -> QualityInputs:
    """What the quality report measures an assembled motion against (:mod:`motion.goals`): the
    length; each body, joint and obstacle constraint; each pose constraint as the clip frame's
    pose (and whether that very frame plays there: ``held``, ``frames`` off in its clip); each
    label constraint honoured by the labels of the frames played; ``cuts`` as joins."""
    goals: list[Goal] = [LengthGoal(problem.length)]
    for b in problem.bodies:
        goals.append(BodyGoal(b.name, b.frame, b.xz, b.heading))
    for j in problem.joints:
        goals.append(JointGoal(j.name, j.frame, j.joint, j.position, j.velocity))
    index = {name: i for i, name in enumerate(library.names)}
    n = motion.num_frames
    for p in problem.poses:
        src = library.motions[p.clip]
        frame_pos = src.slice(p.clip_frame, p.clip_frame + 1).global_positions() * src.metres_per_unit
        extra: dict[str, Any] = {"held": False, "frames": None}
        if p.frame < n:
            clip, at = provenance[p.frame]
            same = index[clip] == p.clip
            extra = {"held": same and at == p.clip_frame, "frames": abs(at - p.clip_frame) if same else None}
        goals.append(PoseGoal(p.name, p.frame, body_pose(frame_pos, src.skeleton)[0], extra=extra))
    starts = np.concatenate(([0], np.cumsum([m.num_frames for m in library.motions])))
    rows = np.array([starts[index[c]] + f for c, f in provenance], dtype=np.int64)
    for lb in problem.labels:
        t = np.arange(lb.start, lb.end)
        honoured = np.zeros(t.size, dtype=bool)
        inside = t < n
        honoured[inside] = (lb.good[rows[t[inside]] + 1] - lb.good[rows[t[inside]]]) > 0
        goals.append(LabelGoal(lb.name, lb.label, lb.start, lb.end, lb.value, honoured))
    for ob in problem.obstacles:
        goals.append(ObstacleGoal(ob.name, ob.region))
    return QualityInputs(goals=tuple(goals), joins=np.asarray(cuts, dtype=np.intp))
