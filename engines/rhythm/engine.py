"""The rhythmic synthesis engine (Kim, Park & Shin 2003) as the runtime sees it.

Database kind ``rhythm`` (:class:`schemas.rhythm.RhythmDatabaseSpec`): ``build`` analyses the
motion beats of the examples, cuts them into basic movements, groups them and builds the movement
transition graph (:mod:`engines.rhythm.build`). Request ``engine: "rhythm"``
(:class:`schemas.rhythm.RhythmRequest`): the music's beats (:mod:`engines.rhythm.music`), a walk
of the graph with blended, time-warped movements (:mod:`engines.rhythm.synth`), optional control
(per-beat direction/speed, a path to follow in formation, crowds steering around each other,
couples), foot cleanup, and a report with the music beats, the motion beats detected in the
output and the beat-align scores; couples with ``hand_hold`` get the hold measured (``hold[c]``,
beside the example couples' own) and, with ``reach``, tightened (:mod:`engines.rhythm.hold`).

Output: one character is a plain motion on the database skeleton. Several characters (or a
couple) are one motion on a combined skeleton: a static ``world`` root with each character's
skeleton under it, joint names prefixed ``c0_``, ``c1_``... (couples: ``c0_lead_``,
``c0_follow_``), each character's hip carrying position channels (:mod:`engines.combine`).
Provenance follows character 0 (the leader of couple 0).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import numpy.typing as npt

from motion import Motion, MotionError, Skeleton
from motion.goals import BeatGoal, Character, Goal, HoldGoal, LengthGoal, Point, hold_figures
from motion.metrics import beat_align_scores
from motion.plausibility import SPEED_P99_MARGIN, SPEED_WINDOW_S
from motion.quality import QualityInputs
from schemas.movement_graph import DerivedFrom, GraphEdits, MovementGraph, ResolvedEdit
from schemas.rhythm import RhythmDatabaseSpec, RhythmRequest

from ..base import (
    Arrays,
    DatabaseArrays,
    DatabaseFacts,
    Emitter,
    Engine,
    EngineError,
    KindSummary,
    LiveSession,
    OutputEstimate,
    Role,
    Run,
    ShouldStop,
    Solution,
    Stopped,
)
from ..combine import combine_motions, combined_characters
from ..library import MotionLibrary
from .build import build_rhythm
from .choreography import edited_arrays, movement_graph, resolve_edits
from .database import RhythmDatabase
from .music import MusicError, bpm_beats, parse_midi
from .music_facts import audio_facts, channel_problem, midi_facts, wav_channels
from .session import LiveDancer
from .synth import Control, Dancers, SpeedLimits, Tables, initial_dancers, synthesize

Array = npt.NDArray[np.float64]


def music_beats(request: RhythmRequest, beats_per_movement: int = 1) -> Array:
    """``(B,)`` beat times in seconds of the request's music (:class:`schemas.rhythm.Music`).

    When a recording's downbeat is found, movements (``beats_per_movement`` beats each) start on
    the bar: the beats before the first downbeat are completed to a whole movement with beats at
    the opening period (dropped instead if those would fall before 0 s)."""
    music = request.music
    try:
        if music.bpm is not None and music.duration_s is not None:  # the schema gives both or neither
            beats = bpm_beats(music.bpm, music.duration_s, music.offset_s)
        elif music.midi is not None:
            beats = parse_midi(_input(request, music.midi)).beat_times()
        elif music.audio is not None:
            from .audio import audio_beats  # librosa: imported only when a recording is used

            found = audio_beats(_input(request, music.audio), music.tempo_bpm)
            beats = _on_the_bar(found.beats_s, found.downbeat, beats_per_movement)
        else:
            beats = np.asarray(music.beats_s, dtype=np.float64)
    except MusicError as exc:
        raise EngineError(f"music: {exc}") from None
    if music.bpm is None and music.duration_s is not None:
        beats = beats[beats <= music.duration_s + 1e-9]
    if beats.size < 2:
        raise EngineError(f"the music holds {beats.size} beat(s); at least 2 are needed to dance")
    if beats[-1] > 3600:
        raise EngineError("the music is longer than an hour")
    return beats


@dataclass(frozen=True, slots=True)
class MusicEstimate:
    """What a request's music adds to its budget before the search: its length in seconds (None:
    unknown), the bytes decoding it holds, and problems (sentences) found in its header."""

    seconds: float | None = None
    decode_bytes: int = 0
    problems: tuple[str, ...] = ()


def music_estimate(request: RhythmRequest) -> MusicEstimate:
    """The music's length as far as known before the search, from headers and capped counts only
    (:mod:`engines.rhythm.music_facts`: bounded time and memory whatever the file holds): a fixed
    tempo's duration, the last given beat, a MIDI file's end, a recording's header; ``duration_s``
    bounds each."""
    music = request.music
    if music.bpm is not None and music.duration_s is not None:  # the schema gives both or neither
        return MusicEstimate(float(music.duration_s))
    length: float | None = None
    decode = 0
    problems: tuple[str, ...] = ()
    if music.beats_s is not None:
        length = float(music.beats_s[-1])
    elif music.midi is not None:
        midi = midi_facts(_attached(request, music.midi))
        length, problems = midi.duration_s, midi.problems
    elif music.audio is not None:
        data = _attached(request, music.audio)
        audio = audio_facts(data)
        if audio is not None:
            length, decode = audio.duration_s, audio.decoded_bytes
        too_many = channel_problem(audio.channels if audio is not None else wav_channels(data))
        problems = (too_many,) if too_many is not None else ()
    if music.duration_s is not None:
        length = float(music.duration_s) if length is None else min(length, float(music.duration_s))
    return MusicEstimate(length, decode, problems)


def _attached(request: RhythmRequest, ref: str) -> bytes:
    """An input file's bytes, or none when the caller estimates without the files attached."""
    try:
        return bytes(request.input_bytes(ref))
    except KeyError:
        return b""


def _on_the_bar(beats: Array, downbeat: int | None, per_movement: int) -> Array:
    """``beats`` shifted by whole beats so that the ``downbeat`` starts a movement (doc above)."""
    lead = 0 if downbeat is None or per_movement < 2 else downbeat % per_movement
    if lead == 0 or beats.size < 2:
        return beats
    period = float(beats[1] - beats[0])
    before = beats[0] - period * np.arange(per_movement - lead, 0, -1)
    return np.concatenate((before, beats)) if before[0] >= 0 else beats[lead:]


def _input(request: RhythmRequest, ref: str) -> bytes:
    try:
        return bytes(request.input_bytes(ref))
    except KeyError as exc:
        raise EngineError(str(exc.args[0])) from None


def _path_control(
    path: Array, speed: float, beats: Array, b: int, duration: float, offsets: Array
) -> Callable[[int, Dancers], Control]:
    """Follow ``path (P, 2)`` at ``speed`` m/s, each character on the offset curve given by its
    formation slot ``offsets (C, 2)`` (lateral x, longitudinal z) — marching rows keep their
    formation through turns because each row follows its own offset curve."""
    seg = np.diff(path, axis=0)
    seg_len = np.linalg.norm(seg, axis=1)
    keep = seg_len > 1e-9
    if not keep.any():
        raise EngineError("the path needs two distinct points")
    valid = np.flatnonzero(keep)
    cum = np.concatenate(([0.0], np.cumsum(seg_len)))
    total = float(cum[-1])

    def point(s: Array) -> tuple[Array, Array]:
        s = np.clip(s, 0.0, total)
        i = np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(seg) - 1)
        i = valid[np.minimum(np.searchsorted(valid, i), valid.size - 1)]  # skip zero-length segments
        tangent = seg[i] / seg_len[i, None]
        return path[i] + tangent * (s - cum[i])[:, None], tangent

    def control(beat: int, d: Dancers) -> Control:
        t_end = beats[min(beat + b, beats.size - 1)] - beats[0]
        s = speed * t_end + offsets[:, 1]
        p, tangent = point(s)
        side = np.stack((tangent[:, 1], -tangent[:, 0]), axis=-1)  # the path frame's +X (the body's left)
        goal = p + side * offsets[:, 0:1]
        delta = goal - d.pos
        dist = np.linalg.norm(delta, axis=1)
        head = np.arctan2(delta[:, 0], delta[:, 1])
        return Control(speed=np.clip(dist / duration, 0.0, 2.5 * max(speed, 0.1)), heading=head)

    return control


def _directions_control(keys: list[Any], default_speed: float | None) -> Callable[[int, Dancers], Control]:
    beats_k = np.array([k.beat for k in keys])
    heads = np.radians(np.array([k.heading_deg for k in keys]))
    speeds = []
    cur = np.nan if default_speed is None else default_speed
    for k in keys:
        cur = k.speed if k.speed is not None else cur
        speeds.append(cur)
    spd = np.array(speeds, dtype=np.float64)

    def control(beat: int, d: Dancers) -> Control:
        i = int(np.searchsorted(beats_k, beat, side="right")) - 1
        if i < 0:
            return Control(
                speed=np.full(d.count, np.nan if default_speed is None else default_speed),
                heading=np.full(d.count, np.nan),
            )
        return Control(speed=np.full(d.count, spd[i]), heading=np.full(d.count, heads[i]))

    return control


def _with_avoidance(
    inner: Callable[[int, Dancers], Control] | None, radius: float, default_speed: float
) -> Callable[[int, Dancers], Control | None]:
    """Add a separation force (Helbing-style social force, 1/d falloff inside ``radius``) to the
    desired direction; characters with no other target only steer when someone is near."""

    def control(beat: int, d: Dancers) -> Control | None:
        base = inner(beat, d) if inner is not None else None
        diff = d.pos[:, None, :] - d.pos[None, :, :]  # (C, C, 2): C characters, not database frames
        dist = np.linalg.norm(diff, axis=-1)
        np.fill_diagonal(dist, np.inf)
        near = dist < radius
        if not near.any():
            return base
        push = ((radius - np.minimum(dist, radius)) / radius / np.maximum(dist, 1e-6))[..., None] * diff
        force = push.sum(axis=1)  # (C, 2)
        mag = np.linalg.norm(force, axis=1)
        if base is None:
            base = Control(speed=np.full(d.count, np.nan), heading=np.full(d.count, np.nan))
        want = np.where(
            np.isnan(base.heading)[:, None],
            np.zeros((d.count, 2)),
            np.stack((np.sin(base.heading), np.cos(base.heading)), axis=-1),
        )
        steer = want + force
        pushed = mag > 1e-6
        heading = np.where(pushed, np.arctan2(steer[:, 0], steer[:, 1]), base.heading)
        speed = np.where(pushed & np.isnan(base.speed), np.minimum(mag, 1.0) * default_speed, base.speed)
        return Control(speed=speed, heading=heading)

    return control


class RhythmEngine(Engine[RhythmRequest, RhythmDatabaseSpec]):
    """Music-synchronized rhythmic motion from a movement transition graph (module doc)."""

    name = "rhythm"
    kind = "rhythm"
    request_model = RhythmRequest
    spec_model = RhythmDatabaseSpec

    @classmethod
    def estimate(cls, request: RhythmRequest, facts: DatabaseFacts) -> OutputEstimate:
        """The music's length (:func:`music_estimate`) at the output rate, per dancer (two per
        couple); 400 bytes per joint-frame, plus a recording's decoding."""
        base = super().estimate(request, facts)
        music = music_estimate(request)
        frames = None if music.seconds is None else round(music.seconds * base.fps)
        return replace(
            base,
            frames=frames,
            bytes_per_joint_frame=400,
            input_bytes=music.decode_bytes,
            problems=music.problems,
        )

    @classmethod
    def summarize(cls, stored_spec: Mapping[str, Any], arrays: DatabaseArrays) -> KindSummary:
        """The couples' roles (leader, follower)."""
        roles: dict[str, Role] = {}
        for couple in stored_spec.get("partners") or []:
            roles[couple["leader"]] = "leader"
            roles[couple["follower"]] = "follower"
        return KindSummary(roles=roles, couples=bool(stored_spec.get("partners")))

    @classmethod
    def check_movement_graph(cls, database_id: str) -> None:
        """Every rhythm database has one."""

    @classmethod
    def movement_graph(
        cls,
        arrays: DatabaseArrays,
        database_id: str,
        stored_spec: Mapping[str, Any],
        derived_from: DerivedFrom | None = None,
    ) -> MovementGraph:
        """The movement transition graph (:func:`engines.rhythm.choreography.movement_graph`)."""
        w1 = stored_spec.get("kinematic_weight")
        return movement_graph(arrays, database_id, float(w1) if w1 is not None else None, derived_from)

    @classmethod
    def recording_beats(cls, data: bytes, tempo_bpm: float | None = None) -> dict[str, Any]:
        """The beats of a recording (:func:`engines.rhythm.audio.audio_beats`): its length, tempo
        (with ``tempo_confidence`` in [0, 1], how clearly the onsets pick this metrical level over
        the others, 0.5 = another is as likely, None when ``tempo_bpm`` was given), beat times and
        downbeat (None when no downbeat is clear), seconds rounded to the microsecond."""
        from .audio import audio_beats  # librosa: imported only when a recording is read

        try:
            found = audio_beats(data, tempo_bpm)
        except MusicError as exc:
            raise EngineError(str(exc)) from None
        return {
            "duration_s": round(found.duration_s, 6),
            "tempo_bpm": round(found.tempo_bpm, 4),
            "tempo_confidence": found.tempo_confidence,
            "beats_s": [round(float(t), 6) for t in found.beats_s],
            "downbeat_s": None if found.downbeat is None else round(float(found.beats_s[found.downbeat]), 6),
        }

    @classmethod
    def edit_movement_graph(
        cls, arrays: DatabaseArrays, edits: GraphEdits, database_id: str
    ) -> tuple[list[ResolvedEdit], Arrays]:
        """The edits resolved and the edited arrays (:mod:`engines.rhythm.choreography`); raises
        :class:`~engines.rhythm.choreography.GraphEditError` naming the edit that breaks a rule."""
        resolved = resolve_edits(edits.edits, arrays)
        return resolved, edited_arrays(arrays, resolved)

    def __init__(self, library: MotionLibrary, arrays: Arrays) -> None:
        super().__init__(library, arrays)
        self.tables: Tables
        self.meta: dict[str, Any]
        stored = RhythmDatabase.from_arrays(arrays)
        self.tables, self.meta = stored.tables(), stored.meta
        leaders = self.meta["leaders"]
        followers = self.meta["followers"]
        self.leader_skeleton = library.clip(leaders[0]).skeleton
        self.follower_skeleton = library.clip(followers[0]).skeleton if followers and followers[0] else None

    @classmethod
    def build(
        cls, spec: RhythmDatabaseSpec, library: MotionLibrary, emit: Emitter, should_stop: ShouldStop
    ) -> Arrays:
        return build_rhythm(spec, library, emit, should_stop)

    @property
    def speed_limits(self) -> SpeedLimits:
        """What the beat accent must not drive the body beyond: the examples' fastest turn rate,
        and their fastest speed but no more than the quality report allows the 99th percentile
        (:data:`motion.plausibility.SPEED_P99_MARGIN` times the examples')."""
        ref = self.quality_reference
        speed = min(ref.root_speed_max, SPEED_P99_MARGIN * ref.root_speed_p99)
        return SpeedLimits(speed, ref.turn_rate_max, SPEED_WINDOW_S)

    # -- synthesis ----------------------------------------------------------------------------
    def make_control(
        self, request: RhythmRequest, beats: Array, dancers: Dancers
    ) -> Callable[[int, Dancers], Control | None] | None:
        """The per-movement control of a request (None: free dancing)."""
        t = self.tables
        duration = t.beats_per_movement * float(np.median(np.diff(beats)))
        inner: Callable[[int, Dancers], Control] | None = None
        if request.path is not None:
            path = np.asarray(request.path, dtype=np.float64)
            start = dancers.pos.copy()
            # formation slots relative to the first character, in the path's initial frame
            tan = path[1] - path[0]
            yaw0 = float(np.arctan2(tan[0], tan[1]))
            rel = start - start[:1]
            c, s = np.cos(-yaw0), np.sin(-yaw0)
            offsets = np.stack((c * rel[:, 0] + s * rel[:, 1], -s * rel[:, 0] + c * rel[:, 1]), axis=-1)
            inner = _path_control(
                path,
                0.8 if request.speed is None else request.speed,
                beats,
                t.beats_per_movement,
                duration,
                offsets,
            )
        elif request.directions is not None:
            inner = _directions_control(request.directions, request.speed)
        elif request.speed is not None:
            spd = float(request.speed)

            def inner_speed(beat: int, d: Dancers) -> Control:
                return Control(speed=np.full(d.count, spd), heading=d.yaw.copy())

            inner = inner_speed
        if request.avoid and dancers.count > 1:
            return _with_avoidance(inner, 0.9 * request.spacing_m, 0.5)
        return inner

    def synthesize(self, request: RhythmRequest, beats: Array) -> tuple[list[Motion], list[Motion], Any]:
        """Character motions (leaders), partner motions (couples) and the raw rendering."""
        t = self.tables
        if request.couples and not t.couples:
            raise EngineError("couples need a database built with 'partners'")
        fps = float(request.fps or t.fps)
        start = request.start
        start_xz = np.asarray(start.position if start else (0.0, 0.0), dtype=np.float64)
        start_yaw = float(np.radians(start.heading_deg)) if start else 0.0
        dancers = initial_dancers(
            request.characters, request.formation, request.spacing_m, start_xz, start_yaw
        )
        control = self.make_control(request, beats, dancers)
        rng = np.random.default_rng(request.seed)
        r = synthesize(t, beats, fps, dancers, rng, control, accent=request.accent, limits=self.speed_limits)
        leaders = [
            Motion(self.leader_skeleton, r.root[c], r.rot[c], fps, r.jt[c], "m", f"rhythm_{c}")
            for c in range(request.characters)
        ]
        partners: list[Motion] = []
        if (
            request.couples
            and r.proot is not None
            and r.prot is not None
            and self.follower_skeleton is not None
        ):
            partners = [
                Motion(
                    self.follower_skeleton,
                    r.proot[c],
                    r.prot[c],
                    fps,
                    np.zeros((r.proot.shape[1], 0, 3)),
                    "m",
                    f"partner_{c}",
                )
                for c in range(request.characters)
            ]
        return leaders, partners, r

    def hold_goals(self, hold: Any, characters: tuple[Character, ...]) -> list[Goal]:
        """The hand hold of each couple (``characters``: leader, follower, leader...) as a
        :class:`motion.goals.HoldGoal` named ``hold[c]``, with what the example couples do
        (``examples_held_fraction``, ``examples_median_cm``: the same joints, the same distance)."""
        ends = self._hold_joints(hold)
        max_m = float(hold.max_cm) / 100
        extra = self._example_hold(ends[0], ends[1], max_m)
        out: list[Goal] = []
        for c in range(len(characters) // 2):
            lead, follow = characters[2 * c], characters[2 * c + 1]
            a = Point(2 * c, int(lead.joints[ends[0]]), f"c{c}_lead.{hold.leader_joint}")
            b = Point(2 * c + 1, int(follow.joints[ends[1]]), f"c{c}_follow.{hold.follower_joint}")
            out.append(HoldGoal(f"hold[{c}]", a, b, max_m, float(hold.min_fraction), extra))
        return out

    def _hold_joints(self, hold: Any) -> tuple[int, int]:
        """The leader's and the follower's joint of a hand hold (an error naming the joints)."""
        follower = self.follower_skeleton
        if follower is None:  # pragma: no cover - couples need partners, checked by synthesize
            raise EngineError("couples need a database built with 'partners'")
        ends: list[int] = []
        for role, sk, name in (
            ("leader", self.leader_skeleton, hold.leader_joint),
            ("follower", follower, hold.follower_joint),
        ):
            try:
                ends.append(int(sk.index(name)))
            except MotionError:
                raise EngineError(
                    f"hand_hold: the {role} has no joint named {name!r}; joints: {', '.join(sk.names)}"
                ) from None
        return ends[0], ends[1]

    def _example_hold(self, lead_joint: int, follow_joint: int, max_m: float) -> dict[str, float]:
        """The hold figures of the example couples (leader and follower clips captured together)."""
        dists = []
        for lead, follow in zip(self.meta["leaders"], self.meta["followers"], strict=False):
            if not follow:
                continue
            a, b = self.library.clip(lead), self.library.clip(follow)
            n = min(a.num_frames, b.num_frames)
            pa = a.global_positions()[:n, lead_joint] * a.metres_per_unit
            pb = b.global_positions()[:n, follow_joint] * b.metres_per_unit
            dists.append(np.linalg.norm(pa - pb, axis=-1))
        if not dists:
            return {}
        fig = hold_figures(np.concatenate(dists), max_m)
        return {"examples_held_fraction": fig["held_fraction"], "examples_median_cm": fig["median_cm"]}

    @classmethod
    def check_live_session(cls, database_id: str) -> None:
        """Every rhythm database dances live."""

    def live_session(self, *, seed: int = 0, fps: float | None = None, accent: float = 0.6) -> LiveSession:
        """A dancer driven by beats as they happen (:class:`engines.rhythm.session.LiveDancer`)."""
        return LiveDancer(self, seed=seed, fps=fps, accent=accent)

    def search(self, request: RhythmRequest, run: Run) -> Stopped:
        """One pass over the music (the search's work: one walk of the movement graph drawn from
        the request's seed, so the same request gives the same bytes on any machine). The pass is
        short and always completes: the time cap never cuts it (``Stopped.work``); a cancel before
        the foot cleanup ends it without an answer (``Stopped.cancelled``)."""
        emit = run.emit
        beats = music_beats(request, self.tables.beats_per_movement)
        emit.progress(0.1, f"{beats.size} music beats")
        leaders, partners, r = self.synthesize(request, beats)
        mode = request.feet_mode()
        if mode != "free":
            lock = mode == "lock"
            leaders = [_clean(m, self.foot_floor(m.skeleton), lock) for m in leaders]
            partners = [_clean(m, self.foot_floor(m.skeleton), lock) for m in partners]
            if run.cancelled():
                return Stopped.cancelled
        hold = request.hand_hold
        if hold is not None and hold.reach and partners:
            from .hold import hold_hands

            lj, fj = self._hold_joints(hold)
            for c in range(len(partners)):
                leaders[c], partners[c] = hold_hands(
                    leaders[c], partners[c], lj, fj, float(hold.max_cm) / 100
                )
        first = leaders[0]
        pos0 = first.global_positions()
        mint, bail, speed_minima = beat_align_scores(pos0, first.fps, beats)
        motion_beats = _motion_beats(first)
        inner = beats[(beats >= 0) & (beats <= first.duration_s)]
        if motion_beats.size and inner.size:
            err = np.abs(motion_beats[:, None] - inner[None, :]).min(axis=1)
            beat_err = float(np.mean(err))
        else:
            beat_err = float("nan")
        motion = _assemble(leaders, partners, request.couples)
        names = self.meta["examples"]
        src = self.tables.src_frames
        dom = r.dominant[0]
        u = r.u
        i0 = np.minimum(np.floor(u).astype(np.intp), src.shape[1] - 1)
        frames = np.rint(src[dom, i0]).astype(np.int64)
        provenance = [(names[int(self.tables.src_clip[m])], int(f)) for m, f in zip(dom, frames, strict=True)]
        movements = [
            dict(
                p,
                clips=[names[int(self.tables.src_clip[m])] for m in p["members"]],
                source_start_frames=[int(round(float(src[m, 0]))) for m in p["members"]],
            )
            for p in r.plans
        ]
        terms = {
            "beat_error_s": beat_err if np.isfinite(beat_err) else 0.0,
            "misaligned": 1.0 - 0.5 * (mint + bail),
        }
        chars: list[tuple[str, Skeleton]] = []
        for c, lead in enumerate(leaders):
            chars.append((f"c{c}_lead" if partners else f"c{c}", lead.skeleton))
            if partners:
                chars.append((f"c{c}_follow", partners[c].skeleton))
        joins = np.array([p["start_frame"] for p in r.plans if p["start_frame"] > 0], dtype=np.intp)
        characters = combined_characters(chars, motion) if motion is not first else ()
        goals: list[Goal] = [
            LengthGoal(int(np.floor(beats[-1] * first.fps + 1e-9)) + 1),
            BeatGoal("music", beats),
        ]
        if request.hand_hold is not None and partners:
            goals += self.hold_goals(request.hand_hold, characters)
        inputs = QualityInputs(goals=tuple(goals), characters=characters, joins=joins)
        solution = Solution(
            motion=motion,
            score=terms["misaligned"],
            terms=terms,
            provenance=provenance,
            metrics={
                "music_bpm": 60.0 / float(np.median(np.diff(beats))),
                "characters": float(request.characters),
            },
            annotations={
                "music_beats_s": [round(float(b), 4) for b in beats],
                "motion_beats_s": [round(float(b), 4) for b in motion_beats],
                "speed_minima_s": [round(float(b), 4) for b in speed_minima],
                "movements": movements,
                "characters": request.characters,
                "couples": bool(request.couples),
            },
        )
        emit.solution(self.finish(solution, inputs))
        return Stopped.work


def _clean(m: Motion, floor: dict[int, tuple[float, float]], lock: bool = True) -> Motion:
    """Planted feet kept still (``lock``; their height only without it) at the examples' planted
    height of each foot joint, and no foot lower than the examples' lowest (``floor``: joint ->
    (planted, lowest) metres): blending movements and fading their joins moves the body up and
    down and swings legs through the floor."""
    from motion.contacts import detect_contacts
    from motion.footskate import remove_foot_skate

    try:
        joints, flags = detect_contacts(m)
        if not floor or not all(int(j) in floor for j in joints):
            return remove_foot_skate(m, (joints, flags), horizontal=lock)
        rest = np.array([floor[int(j)][0] for j in joints])
        lowest = np.array([floor[int(j)][1] for j in joints])
        return remove_foot_skate(
            m,
            (joints, flags),
            heights=np.broadcast_to(rest, flags.shape).copy(),
            floor=lowest,
            horizontal=lock,
        )
    except MotionError:
        return m  # no feet found by name: nothing to keep planted


def _motion_beats(m: Motion) -> Array:
    from motion.beats import detect_beats

    try:
        return np.asarray(detect_beats(m).times_s)
    except MotionError:
        return np.zeros(0)


def _assemble(leaders: list[Motion], partners: list[Motion], couples: bool) -> Motion:
    if len(leaders) == 1 and not partners:
        return leaders[0]
    chars: list[Motion] = []
    prefixes: list[str] = []
    for c, m in enumerate(leaders):
        chars.append(m)
        prefixes.append(f"c{c}_lead_" if couples else f"c{c}_")
        if partners:
            chars.append(partners[c])
            prefixes.append(f"c{c}_follow_")
    return combine_motions(chars, prefixes, "rhythm")
