"""A live rhythmic-dance session: one character dancing to beats that arrive as they happen.

This is the synthesis of :mod:`engines.rhythm.synth` driven one beat at a time (the paper's
on-line mode, Sec. 5): at every beat a movement beat is rendered over the predicted beat
interval, so a client that plays each batch when it arrives shows the motion beat on the music
beat, with at most one beat of latency. A new movement (graph step + blend) starts every
``beats_per_movement`` beats; direction/speed changes apply from the next movement. The service's
WebSocket (``service/routes/sessions.py``) only moves messages; this class holds the state.
"""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np
import numpy.typing as npt

from motion import Skeleton

from .beatkeys import warp_frames
from .synth import (
    Control,
    MovementPlan,
    SpeedLimits,
    Tables,
    accented,
    bounded_accent,
    initial_dancers,
    plan_movement,
    render,
)

Array = npt.NDArray[np.float64]

MIN_PERIOD_S = 0.2
MAX_PERIOD_S = 3.0


class DancingEngine(Protocol):
    """What a live dancer needs of a loaded rhythm engine (:class:`engines.rhythm.engine.RhythmEngine`)."""

    tables: Tables
    leader_skeleton: Skeleton

    @property
    def speed_limits(self) -> SpeedLimits: ...


class LiveDancer:
    """Beat-by-beat synthesis for one character (not thread-safe: one session, one caller at a time).

    Parameters
    ----------
    engine: a loaded rhythm engine.
    seed: random seed of the graph walk.
    fps: output frame rate (default: the database's).
    accent: beat accent of the time warp (see :mod:`engines.rhythm.synth`).
    """

    def __init__(
        self, engine: DancingEngine, seed: int = 0, fps: float | None = None, accent: float = 0.6
    ) -> None:
        self.engine = engine
        self.tables = engine.tables
        self.fps = float(fps or self.tables.fps)
        self.accent = float(accent)
        self.limits = engine.speed_limits
        self.rng = np.random.default_rng(seed)
        self.dancers = initial_dancers(1, "grid", 1.0, np.zeros(2), 0.0)
        self.plan: MovementPlan | None = None
        self.beat_in_movement = self.tables.beats_per_movement
        self.beats = 0
        self.frame = 0
        self.heading: float | None = None
        self.speed: float | None = None

    @property
    def period_s(self) -> float:
        """The examples' beat period, seconds."""
        return float(self.tables.period_s)

    def skeleton_message(self) -> dict[str, Any]:
        """The ``skeleton`` message: joint names, parents, offsets (metres), Euler channel orders."""
        sk = self.engine.leader_skeleton
        return {
            "type": "skeleton",
            "names": list(sk.names),
            "parents": [int(p) for p in sk.parents],
            "offsets": np.round(sk.offsets, 5).tolist(),
            "fps": self.fps,
            "beats_per_movement": self.tables.beats_per_movement,
            "rotation": "local quaternions (x, y, z, w); root position metres, Y up",
        }

    def steer(self, heading_deg: float | None, speed: float | None) -> None:
        """Direction (degrees about +Y, 0 = +Z) and speed (m/s) for the next movements (None: free)."""
        self.heading = None if heading_deg is None else float(np.radians(heading_deg))
        self.speed = speed

    def _control(self) -> Control | None:
        if self.heading is None and self.speed is None:
            return None
        return Control(
            speed=np.array([np.nan if self.speed is None else self.speed]),
            heading=np.array([np.nan if self.heading is None else self.heading]),
        )

    def beat(self, period_s: float) -> dict[str, Any]:
        """Render the beat starting now, lasting ``period_s`` seconds (clipped to [0.2, 3] s).

        Returns the ``frames`` message: ``{"type", "start", "fps", "beat", "root": (n, 3),
        "rotations": (n, J, 4)}``."""
        period = float(np.clip(period_s, MIN_PERIOD_S, MAX_PERIOD_S))
        t = self.tables
        if self.plan is None or self.beat_in_movement >= t.beats_per_movement:
            self.plan = plan_movement(t, self.dancers, self._control(), self.rng)
            self.beat_in_movement = 0
        n = max(1, int(round(period * self.fps)))
        x = np.arange(n) / n
        beat = np.full(n, self.beat_in_movement, dtype=np.intp)
        a = bounded_accent(t, self.plan, beat, x, self.accent, self.limits, self.fps)
        u = warp_frames(t.plan_keys(self.plan), beat, accented(x, a))
        r = render(t, self.plan, u)
        msg = {
            "type": "frames",
            "start": self.frame,
            "fps": self.fps,
            "beat": self.beats,
            "root": np.round(r.root[0], 4).tolist(),
            "rotations": np.round(r.rot[0], 5).tolist(),
        }
        self.beat_in_movement += 1
        self.beats += 1
        self.frame += n
        return msg
