"""Building a rhythm database: motion beats -> basic movements -> groups -> transition graph.

:func:`build_rhythm` is the engine's ``build``: it analyses the motion beats of every example
(:func:`motion.beats.detect_beats`, or the spec's ``clip_beats``), cuts and normalizes the basic
movements (:mod:`engines.rhythm.movements`), groups them (:mod:`engines.rhythm.movement_graph`), builds the
movement transition graph and stores everything as ``rhythm.*`` arrays
(:class:`engines.rhythm.database.RhythmDatabase`, which also loads them for synthesis).

Two choices the paper leaves open:

* **One tempo octave for all examples.** Beat analysis can lock onto half or double the step rate of
  a dance (a periodogram has peaks at the harmonics). Examples of one dance share a meter, so after a
  first pass the tempi are folded onto one octave (the circular mean of ``log2(bpm)``), the octave
  taken is the fastest inside the spec's ``tempo_bpm`` prior, and every example is analysed again
  with the prior narrowed to +-20 % around it (``harmonize_tempo``).
* **Beats at speed minima.** Each motion beat is moved to the nearest local minimum of the summed
  joint speed within a quarter period (``beat_snap``): the moment of "distinctive directional
  change" the candidates approximate, and what a viewer (and the beat-align scores) see as the beat.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from scipy.ndimage import gaussian_filter1d
from scipy.signal import argrelextrema

from motion import Motion, MotionError
from motion.mirror import joint_frames, mirror
from schemas.rhythm import RhythmDatabaseSpec

from ..base import Arrays, Emitter, EngineError, ShouldStop
from ..library import MotionLibrary
from .beatkeys import beat_keys, movement_speed
from .database import RhythmDatabase
from .movement_graph import k_medoids, medoids, subtractive_clustering, transition_graph
from .movements import Example, Movements, extract_movements, movement_differences, transition_differences
from .reach import describe as describe_graph

Array = npt.NDArray[np.float64]


SNAP_SMOOTH_S = 0.08
"""Smoothing of the total joint speed before beats are snapped to its minima, seconds."""

SNAP_WINDOW = 0.3
"""Beats move at most this fraction of the median beat period when snapped."""


def total_speed(motion: Motion) -> Array:
    """``(F,)`` summed speed of all joints (m/s), central differences."""
    pos = motion.global_positions() * motion.metres_per_unit
    if motion.num_frames < 2:
        return np.zeros(motion.num_frames)
    v = np.linalg.norm(np.gradient(pos, axis=0), axis=-1).sum(axis=1) * motion.fps
    return np.asarray(v)


def speed_dips(speed: Array, fps: float, smooth_s: float = SNAP_SMOOTH_S) -> Array:
    """Times (s) of the local minima of the total joint speed smoothed by ``smooth_s`` seconds."""
    s = gaussian_filter1d(speed, max(1.0, smooth_s * fps))
    return np.asarray(argrelextrema(s, np.less)[0] / fps)


def snap_to_speed_minima(beats_s: Array, dips_s: Array, window_s: float) -> Array:
    """Each beat moved to the nearest speed dip (:func:`speed_dips`) within ``+-window_s`` (kept
    where there is none); beats stay strictly increasing (a beat that would not advance stays put)."""
    out = np.array(beats_s, dtype=np.float64)
    if dips_s.size == 0:
        return out
    i = np.clip(np.searchsorted(dips_s, out), 1, max(dips_s.size - 1, 1))
    cand = np.stack((dips_s[i - 1], dips_s[np.minimum(i, dips_s.size - 1)]), axis=1)
    near = cand[np.arange(out.size), np.argmin(np.abs(cand - out[:, None]), axis=1)]
    moved = np.where(np.abs(near - out) <= window_s, near, out)
    keep = np.concatenate(([True], np.diff(moved) > 1e-3))
    return np.asarray(np.where(keep, moved, out))


def dip_agreement(beats_s: Array, dips_s: Array, sigma_s: float = 0.05) -> float:
    """Mean over beats of ``exp(-d^2 / 2 sigma^2)``, ``d`` = distance to the nearest speed dip."""
    if beats_s.size == 0 or dips_s.size == 0:
        return 0.0
    d = np.abs(beats_s[:, None] - dips_s[None, :]).min(axis=1)
    return float(np.mean(np.exp(-(d**2) / (2 * sigma_s**2))))


def _detect(motion: Motion, spec: RhythmDatabaseSpec, tempo: tuple[float, float]) -> Array:
    from motion.beats import detect_beats

    return np.asarray(detect_beats(motion, use_positions=spec.use_positions, tempo_bpm=tempo).times_s)


def example_beats(motions: list[Motion], names: list[str], spec: RhythmDatabaseSpec) -> list[Array]:
    """Motion beats (seconds) of each example, harmonized to one tempo octave (module doc)."""
    given = spec.clip_beats or {}
    lo, hi = spec.tempo_bpm
    todo = [i for i, n in enumerate(names) if n not in given]
    dips = [speed_dips(total_speed(m), m.fps) for m in motions]

    def finish(i: int, b: Array) -> Array:
        if spec.beat_snap and b.size > 1:
            return snap_to_speed_minima(b, dips[i], SNAP_WINDOW * float(np.median(np.diff(b))))
        return b

    found = {i: finish(i, _detect(motions[i], spec, (lo, hi))) for i in todo}
    if spec.harmonize_tempo and len(todo) > 1:
        bpms = np.array([60.0 / np.median(np.diff(found[i])) for i in todo if found[i].size > 1])
        if bpms.size > 1:
            ang = 2 * np.pi * np.log2(bpms)
            frac = (np.angle(np.exp(1j * ang).mean()) / (2 * np.pi)) % 1.0
            octaves = 2.0 ** (np.arange(-2, 12) + frac)
            inside = np.sort(octaves[(octaves >= lo) & (octaves <= hi)])[::-1][:2]
            best: tuple[float, dict[int, Array]] | None = None
            for ref in inside:  # the fastest octave and the one below: the one whose beats fall on speed dips
                band = (max(lo, ref / 1.2), min(hi, ref * 1.2))
                cand = {i: finish(i, _detect(motions[i], spec, band)) for i in todo}
                score = float(np.mean([dip_agreement(cand[i], dips[i]) for i in todo]))
                if best is None or score > best[0] + 0.02:
                    best = (score, cand)
            if best is not None:
                found = best[1]
    return [np.asarray(given[n], dtype=np.float64) if n in given else found[i] for i, n in enumerate(names)]


def _examples(
    spec: RhythmDatabaseSpec, library: MotionLibrary
) -> tuple[list[Example], list[str], list[str | None]]:
    names = list(library.names)
    if spec.partners:
        used = {p.leader for p in spec.partners} | {p.follower for p in spec.partners}
        extra = [n for n in names if n not in used]
        if extra:
            raise EngineError(
                f"with partners, every clip must be a leader or a follower; not paired: {', '.join(extra)}"
            )
        leads = [library.clip(p.leader) for p in spec.partners]
        follows = [library.clip(p.follower) for p in spec.partners]
        lead_names = [p.leader for p in spec.partners]
        follow_names: list[str | None] = [p.follower for p in spec.partners]
    else:
        leads, follows, lead_names, follow_names = list(library.motions), [], names, [None] * len(names)
    beats = example_beats(leads, lead_names, spec)
    examples = []
    # one convention for every mirror image (motion.mirror.joint_frames over all the clips)
    lead_frames = joint_frames(leads) if spec.mirror and leads else None
    follow_frames = joint_frames(follows) if spec.mirror and follows else None
    for i, (name, m, b) in enumerate(zip(lead_names, leads, beats, strict=True)):
        partner = follows[i] if follows else None
        if partner is not None and partner.num_frames != m.num_frames:
            n = min(partner.num_frames, m.num_frames)
            m, partner = m.slice(0, n), partner.slice(0, n)
        examples.append(Example(name, m, b, partner))
        if spec.mirror:
            image = mirror(partner, follow_frames) if partner is not None else None
            examples.append(Example(name, mirror(m, lead_frames), b, image))
    return examples, lead_names, follow_names


def _align_signs(q: Array, labels: npt.NDArray[np.intp], centre: npt.NDArray[np.intp]) -> Array:
    """Flip quaternions so each lies in the hemisphere of its group medoid's at the same frame and
    joint (sign consistency for blending)."""
    ref = q[centre[labels]]
    dots = np.sum(q * ref, axis=-1, keepdims=True)
    return np.asarray(np.where(dots < 0, -q, q))


def consecutive_runs(
    clip_of: npt.NDArray[np.intp], index_in_clip: npt.NDArray[np.intp]
) -> list[npt.NDArray[np.intp]]:
    """Movement indices in runs of consecutive movements of one clip (a gap where an irregular span
    was left out starts a new run): the observed transitions of the behavioural likelihood."""
    runs: list[npt.NDArray[np.intp]] = []
    for c in np.unique(clip_of):
        members = np.flatnonzero(clip_of == c)
        members = members[np.argsort(index_in_clip[members], kind="stable")]
        breaks = np.flatnonzero(np.diff(index_in_clip[members]) != 1) + 1
        runs.extend(np.split(members, breaks))
    return runs


def build_rhythm(
    spec: RhythmDatabaseSpec, library: MotionLibrary, emit: Emitter, should_stop: ShouldStop
) -> Arrays:
    """The ``rhythm.*`` arrays of a database (module doc)."""
    emit.progress(0.0, "motion beats")
    try:
        examples, lead_names, follow_names = _examples(spec, library)
    except MotionError as exc:
        raise EngineError(f"beat analysis failed: {exc}") from None
    if should_stop():
        raise InterruptedError
    emit.progress(0.3, "basic movements")
    try:
        mv = extract_movements(examples, spec.beats_per_movement)
    except MotionError as exc:
        raise EngineError(str(exc)) from None
    d = movement_differences(mv, spec.velocity_weight)
    if spec.groups is not None:
        if spec.groups > mv.count:
            raise EngineError(f"groups = {spec.groups} but the examples hold only {mv.count} basic movements")
        labels = k_medoids(d, spec.groups, np.random.default_rng(0))
    else:
        off = d[~np.eye(mv.count, dtype=bool)]
        radius = spec.cluster_radius * float(np.sqrt(np.median(off))) if off.size else 1.0
        labels = subtractive_clustering(d, max(radius, 1e-9), spec.squash, spec.stop_ratio)
    centre = medoids(d, labels)
    if should_stop():
        raise InterruptedError
    emit.progress(0.7, "transition graph")
    td = transition_differences(mv, spec.velocity_weight)
    clip_of = mv.src_clip
    sequences = consecutive_runs(clip_of, mv.index_in_clip)
    graph = transition_graph(
        td,
        labels,
        sequences,
        kinematic_weight=spec.kinematic_weight,
        sigma=spec.sigma,
        threshold=spec.edge_threshold,
        smoothing=spec.count_smoothing,
    )
    emit.progress(0.9, describe_graph(graph.p, graph.start))
    q = _align_signs(mv.rot, labels, centre)
    keys, clarity = _beat_keys(mv, examples[0].motion)
    meta = {
        "frames_per_beat": mv.frames_per_beat,
        "beats_per_movement": mv.beats_per_movement,
        "period_s": mv.period_s,
        "fps": mv.fps,
        "examples": [e.name for e in examples],
        "mirrored": [bool(spec.mirror and i % 2 == 1) for i in range(len(examples))],
        "leaders": lead_names,
        "followers": follow_names,
        "beats_s": {e.name: [round(float(x), 4) for x in e.beats_s] for e in examples},
        "groups": int(labels.max()) + 1,
    }
    partner_root = partner_rot = None
    if mv.partner_root is not None and mv.partner_rot is not None:
        ref = mv.partner_rot[centre[labels]]
        partner_root = mv.partner_root
        partner_rot = np.where(
            np.sum(mv.partner_rot * ref, axis=-1, keepdims=True) < 0, -mv.partner_rot, mv.partner_rot
        )
    return RhythmDatabase(
        meta=meta,
        root=mv.root,
        rot=q,
        jt=mv.jt,
        src_clip=mv.src_clip,
        src_frames=mv.src_frames,
        index_in_clip=mv.index_in_clip,
        end_xz=mv.end_xz,
        end_yaw=mv.end_yaw,
        params=mv.params,
        labels=labels,
        medoids=centre,
        p=graph.p,
        start=graph.start,
        kinematic=graph.kinematic,
        behavioural=graph.behavioural,
        group_distance=graph.group_distance,
        beat_keys=keys,
        clarity=clarity,
        partner_root=partner_root,
        partner_rot=partner_rot,
    ).to_arrays()


def _beat_keys(mv: Movements, example: Motion) -> tuple[Array, Array]:
    """Beat keys and clarity of every movement (:mod:`engines.rhythm.beatkeys`), measured on the
    normalized movements' joint positions (metres)."""
    sk = example.skeleton
    speed = np.stack(
        [
            movement_speed(
                Motion(sk, mv.root[m], mv.rot[m], mv.fps, mv.jt[m], "m", "movement").global_positions()[None]
            )[0]
            for m in range(mv.count)
        ]
    )
    return beat_keys(speed, mv.frames_per_beat, mv.beats_per_movement)
