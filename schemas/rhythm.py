"""Rhythmic synthesis engine (Kim, Park & Shin 2003): database spec and request.

Database: example dances are cut into basic movements every ``beats_per_movement`` motion beats,
grouped, and linked by a movement transition graph. Request: music (a BPM and a duration, a MIDI
file, or an explicit beat list) and optional control (per-beat direction/speed, a path, several
characters, couples).
"""

from __future__ import annotations

from itertools import pairwise
from typing import Annotated, Literal

from pydantic import Field, field_validator, model_validator

from .bases import DatabaseSpecBase, JobRequestBase
from .common import FEET_DESCRIPTION, FeetMode, Strict, feet_mode_of

AUDIO_SUFFIXES = (".wav", ".flac", ".ogg", ".mp3")
"""File name endings of the recordings ``music.audio`` accepts."""


class Partners(Strict):
    """A two-person example: the leader's and the follower's clips (names as in the spec), captured
    together and synchronized frame by frame (e.g. cmu-salsa ``60_XX`` leader, ``61_XX`` follower)."""

    leader: str = Field(min_length=1, max_length=128, examples=["60_01_scaled"])
    follower: str = Field(min_length=1, max_length=128, examples=["61_01_scaled"])


class RhythmDatabaseSpec(DatabaseSpecBase):
    """Rhythmic-motion database: example dances cut into basic movements at motion beats.

    Every clip that is not a follower in ``partners`` is a solo example; each ``partners`` entry is
    also a coupled example (the follower moves with the leader's movements). Motion beats come from
    :func:`motion.beats.detect_beats` unless ``clip_beats`` gives them (seconds from frame 0).
    """

    kind: Literal["rhythm"] = "rhythm"
    beats_per_movement: int = Field(default=4, ge=1, le=16, description="the meter: beats per basic movement")
    groups: int | None = Field(
        default=None, ge=1, le=1000, description="K for k-medoids; absent: subtractive clustering"
    )
    cluster_radius: float = Field(
        default=0.5,
        gt=0,
        le=10,
        description="subtractive clustering radius r, relative to the median distance",
    )
    squash: float = Field(default=1.5, gt=1, le=10, description="subtractive clustering squash factor s > 1")
    stop_ratio: float = Field(
        default=0.15,
        gt=0,
        lt=1,
        description="subtractive clustering stops below this fraction of the first potential",
    )
    velocity_weight: float = Field(default=0.05, ge=0, le=10, description="nu: weight of the velocity terms")
    kinematic_weight: float = Field(
        default=0.5, ge=0, le=1, description="w1 (kinematic likelihood); w2 = 1 - w1 (behavioural)"
    )
    sigma: float | None = Field(
        default=None, gt=0, description="kinematic likelihood scale; default: median group distance"
    )
    edge_threshold: float = Field(
        default=0.02, ge=0, lt=1, description="edges with a likelihood at or below this are dropped"
    )
    count_smoothing: float = Field(
        default=0.5, ge=0, le=100, description="additive smoothing of the observed transition counts"
    )
    tempo_bpm: tuple[float, float] = Field(
        default=(40.0, 200.0), description="motion tempo prior for beat analysis"
    )
    harmonize_tempo: bool = Field(
        default=True,
        description="bring every example's detected tempo to one octave (see engines.rhythm.build)",
    )
    beat_snap: bool = Field(
        default=True, description="move each motion beat to the nearest minimum of total joint speed"
    )
    use_positions: bool = Field(
        default=False, description="beat analysis on joint positions instead of angles"
    )
    mirror: bool = Field(default=False, description="add the mirror image of every example")
    partners: list[Partners] = Field(default_factory=list, max_length=500)
    clip_beats: dict[str, list[float]] | None = Field(
        default=None, description="motion beats per clip name (seconds), instead of detecting them"
    )

    @field_validator("tempo_bpm")
    @classmethod
    def _tempo(cls, v: tuple[float, float]) -> tuple[float, float]:
        if not (0 < v[0] < v[1] <= 1000):
            raise ValueError("tempo_bpm must be [low, high] with 0 < low < high <= 1000")
        return v

    @field_validator("clip_beats")
    @classmethod
    def _beats(cls, v: dict[str, list[float]] | None) -> dict[str, list[float]] | None:
        for name, beats in (v or {}).items():
            if len(beats) < 2 or any(b1 <= b0 for b0, b1 in pairwise(beats)):
                raise ValueError(f"clip_beats[{name!r}] must hold at least 2 strictly increasing times")
            if beats[0] < 0:
                raise ValueError(f"clip_beats[{name!r}]: times must be >= 0 seconds")
        return v

    @model_validator(mode="after")
    def _partners_known(self) -> RhythmDatabaseSpec:
        names = {c.display_name() for c in self.clips}
        for p in self.partners:
            for role, name in (("leader", p.leader), ("follower", p.follower)):
                if name not in names:
                    raise ValueError(
                        f"partners: {role} {name!r} is not a clip of this spec ({', '.join(sorted(names))})"
                    )
            if p.leader == p.follower:
                raise ValueError(f"partners: {p.leader!r} cannot be its own partner")
        for name in self.clip_beats or {}:
            if name not in names:
                raise ValueError(f"clip_beats: {name!r} is not a clip of this spec")
        return self


class Music(Strict):
    """The music to dance to: exactly one of ``bpm`` (with ``duration_s``), ``midi``, ``audio`` or
    ``beats_s``.

    ``duration_s`` is the length of a ``bpm`` piece; with ``midi``, ``audio`` or ``beats_s`` it cuts
    the music after that many seconds. ``audio`` is a recording (WAV, FLAC, Ogg or MP3) whose beats
    are tracked in the worker (:mod:`engines.rhythm.audio`); ``tempo_bpm`` is an optional hint of
    its tempo."""

    bpm: float | None = Field(default=None, gt=0, le=400, examples=[120])
    duration_s: float | None = Field(
        default=None, gt=0, le=3600, examples=[20], description="seconds (required with bpm; a cut otherwise)"
    )
    offset_s: float = Field(default=0.0, ge=0, le=60, description="time of the first beat (bpm only)")
    midi: str | None = Field(default=None, min_length=1, max_length=1024, examples=["song.mid"])
    audio: str | None = Field(
        default=None, min_length=1, max_length=1024, examples=["song.wav"], description="WAV, FLAC, Ogg, MP3"
    )
    tempo_bpm: float | None = Field(
        default=None, ge=30, le=300, description="tempo hint for the beat tracker (audio only), BPM"
    )
    beats_s: list[float] | None = Field(default=None, max_length=100_000)

    @model_validator(mode="after")
    def _one_source(self) -> Music:
        given = [k for k in ("bpm", "midi", "audio", "beats_s") if getattr(self, k) is not None]
        if len(given) != 1:
            raise ValueError(
                "music needs exactly one of 'bpm' (with 'duration_s'), 'midi', 'audio' or 'beats_s'"
            )
        if self.tempo_bpm is not None and self.audio is None:
            raise ValueError("music.tempo_bpm is a hint for 'audio' only")
        name = (self.audio or "").rsplit("/", 1)[-1]
        if "." in name and not name.lower().endswith(AUDIO_SUFFIXES):  # upload ids have no dot
            raise ValueError(f"music.audio {self.audio!r}: expected a .wav, .flac, .ogg or .mp3 file")
        if self.bpm is not None and self.duration_s is None:
            raise ValueError("music with 'bpm' needs 'duration_s' (seconds)")
        if self.beats_s is not None:
            b = self.beats_s
            if len(b) < 2:
                raise ValueError("music.beats_s needs at least 2 beats")
            if b[0] < 0 or any(y <= x for x, y in pairwise(b)):
                raise ValueError("music.beats_s must be strictly increasing times >= 0 (seconds)")
            if b[-1] > 3600:
                raise ValueError("music.beats_s: the last beat must be within 3600 s")
        return self


class DirectionKey(Strict):
    """From beat ``beat`` on (until the next key): move towards ``heading_deg`` (0 = +Z, 90 = +X) at
    ``speed`` m/s (absent: keep the previous speed)."""

    beat: int = Field(ge=0)
    heading_deg: float = Field(ge=-3600, le=3600)
    speed: float | None = Field(default=None, ge=0, le=5)


class StartPose(Strict):
    position: tuple[float, float] = (0.0, 0.0)
    heading_deg: float = 0.0


class HandHold(Strict):
    """Couples: the leader's joint and the follower's joint (a hand hold) within ``max_cm`` of
    each other in at least ``min_fraction`` of the frames, measured on the output by the quality
    report (entry ``hold[c]`` per couple, with what the example couples do)."""

    leader_joint: str = Field(default="lHand", description="joint of the leader's skeleton")
    follower_joint: str = Field(default="rHand", description="joint of the follower's skeleton")
    max_cm: float = Field(default=25.0, gt=0, le=1000)
    min_fraction: float = Field(default=0.5, ge=0, le=1)
    reach: bool = Field(
        default=False,
        description="bring the two hands together by arm IK where they are near (within twice max_cm) "
        "but not within max_cm (engines.rhythm.hold); where the dancers let go, nothing changes",
    )


class RhythmRequest(JobRequestBase):
    """A dance synchronized to music, optionally steered, for one or many characters."""

    engine: Literal["rhythm"] = "rhythm"
    music: Music
    characters: int = Field(default=1, ge=1, le=10_000, description="dancers (or couples) on one clock")
    couples: bool = Field(default=False, description="each character is a couple (needs partners)")
    formation: Literal["grid", "line", "circle", "column"] = "grid"
    spacing_m: float = Field(default=1.5, gt=0, le=50, description="distance between characters")
    start: StartPose | None = None
    path: list[tuple[float, float]] | None = Field(
        default=None, min_length=2, max_length=10_000, description="[x, z] floor points to follow (metres)"
    )
    speed: float | None = Field(default=None, ge=0, le=5, description="travel speed, m/s")
    directions: list[DirectionKey] | None = Field(default=None, max_length=100_000)
    avoid: bool = Field(default=True, description="characters steer around each other")
    accent: float = Field(
        default=0.6,
        ge=0,
        le=0.9,
        description="beat accent: slow the time warp at each music beat by this fraction (0 = linear warp)",
    )
    fps: float | None = Field(default=None, ge=1, le=240, description="output rate (default: the database's)")
    footskate: bool = Field(default=True, description="keep planted feet still (motion.footskate)")
    feet: FeetMode | None = Field(default=None, description=FEET_DESCRIPTION)

    def feet_mode(self) -> FeetMode:
        """The clean-up this request asks for (:func:`schemas.common.feet_mode_of`)."""
        return feet_mode_of(self.footskate, self.feet)

    hand_hold: HandHold | None = Field(
        default=None, description="couples: a hand hold the quality report measures (needs 'couples')"
    )

    @model_validator(mode="after")
    def _control(self) -> RhythmRequest:
        if self.hand_hold is not None and not self.couples:
            raise ValueError("'hand_hold' is a constraint between the partners of a couple: set 'couples'")
        if self.path is not None and self.directions is not None:
            raise ValueError("give either 'path' or 'directions', not both")
        if self.directions is not None:
            beats = [d.beat for d in self.directions]
            if any(b1 <= b0 for b0, b1 in pairwise(beats)):
                raise ValueError("directions must be in increasing beat order")
        return self

    def input_files(self) -> list[str]:
        return [f for f in (self.music.midi, self.music.audio) if f is not None]

    def audio_inputs(self) -> list[str]:
        """The input files that must be audio recordings (checked at submission by their content)."""
        return [self.music.audio] if self.music.audio is not None else []


# -- live session (WebSocket /v1/sessions/rhythm) messages from the client -------------------------
class SessionBeat(Strict):
    """A music beat, now (the server renders the next beat of motion at once)."""

    type: Literal["beat"]


class SessionBpm(Strict):
    """Beats generated by the server at ``bpm`` from now on (a ``beat`` message re-phases them)."""

    type: Literal["bpm"]
    bpm: float = Field(gt=20, le=300)


class SessionDirection(Strict):
    """Travel towards ``heading_deg`` (0 = +Z, 90 = +X) at ``speed`` m/s from the next movement;
    both absent: dance freely."""

    type: Literal["direction"]
    heading_deg: float | None = Field(default=None, ge=-3600, le=3600)
    speed: float | None = Field(default=None, ge=0, le=5)


class SessionStop(Strict):
    """End the session (the server answers ``{"type": "end"}`` and closes with 1000)."""

    type: Literal["stop"]


SessionMessage = Annotated[
    SessionBeat | SessionBpm | SessionDirection | SessionStop, Field(discriminator="type")
]
