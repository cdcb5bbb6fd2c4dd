"""A live control session: the target (follower, walker) generated while the control streams in.

Hsu et al. 2004 solve the whole input at once and leave an on-line variant to future work (Sec. 7).
This is a receding-horizon version of their DP with a **fixed latency** ``L``: output frame ``i`` is
sent as soon as control frame ``i + L`` has arrived, never later. Segments are *committed* (never
changed again) once they start before ``received - L + w`` (``w`` the boundary smoothing half-width,
so every smoothed frame is final when it is sent); when the committed plan no longer reaches that
far, the DP of :mod:`.dp` is solved again over the window from the end of the plan to the newest
control frame (the quick beam stage, then re-timed at the database rate), its first segment scored
for continuity against the last committed one (Eq. 4), and the segments it places early enough are
committed. The last segment of a window is a guess (the leader has not finished it); a latency of
at least the longest segment keeps guesses from being committed. The foot-skate clean-up of the
offline request is not applied (it needs the whole motion).

The service's WebSocket (``service/routes/control_sessions.py``) only moves messages; this class
holds the state. Not thread-safe: one session, one caller at a time.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
import numpy.typing as npt

from motion import Motion

from ..base import EngineError
from .assemble import assemble
from .build import ControlDatabase
from .dp import (
    Infeasible,
    Instances,
    Timed,
    align_points,
    cost_to_go,
    interpretation,
    legal_cells,
    retime,
    solve,
)
from .points import floor_pair_cloud, resample_cloud, trajectory_control
from .schedule import QUICK_CELLS, QUICK_WIDTH


class FollowedEngine(Protocol):
    """What a live follower needs of a loaded control engine
    (:class:`engines.control.engine.ControlEngine`)."""

    db: ControlDatabase
    kept_: npt.NDArray[np.intp]
    solver_instances_: Instances

    def target_motion(self, name: str) -> tuple[Motion, int]: ...


Array = npt.NDArray[np.float64]

MIN_LATENCY_S = 0.5
MAX_LATENCY_S = 5.0
MAX_FRAMES_PER_MESSAGE = 240


@dataclass(slots=True)
class _Plan:
    """The committed segments (database rate, absolute frames): source rows, start, end, alignment
    (``cos, sin, tx, tz``) and target tail points of each."""

    rows: list[tuple[int, int, int]] = field(default_factory=list)  # (pair, source start, length)
    start: list[int] = field(default_factory=list)
    end: list[int] = field(default_factory=list)
    align: list[tuple[float, float, float, float]] = field(default_factory=list)
    tail: list[Array] = field(default_factory=list)  # (Q, 3) target points at the end, source frame

    @property
    def reach(self) -> int:
        """First frame not covered by the plan."""
        return self.end[-1] if self.end else 0


class LiveControl:
    """Frame-by-frame control for one target (see the module doc).

    Parameters
    ----------
    engine: a loaded control engine.
    latency_s: the fixed delay between a control frame arriving and the target frame of the same
        instant being sent, seconds (``[0.5, 5]``; default 1.2, about the longest salsa segment).
    k: continuity weight (default: the database's, :meth:`ControlEngine.continuity_weight`).
    stretch_s, solve_fps, smoothing_s: as in the offline request.
    """

    def __init__(
        self,
        engine: FollowedEngine,
        latency_s: float = 1.2,
        k: float | None = None,
        stretch_s: float = 0.15,
        solve_fps: float = 10.0,
        smoothing_s: float = 0.15,
    ) -> None:
        if not MIN_LATENCY_S <= latency_s <= MAX_LATENCY_S:
            raise EngineError(
                f"latency_s must be within [{MIN_LATENCY_S}, {MAX_LATENCY_S}] s, got {latency_s}"
            )
        self.engine = engine
        self.db = engine.db
        self.fps = float(self.db.fps)
        self.latency = int(round(latency_s * self.fps))
        self.smooth = int(round(smoothing_s * self.fps))
        self.k = float(k) if k is not None else (0.2 if self.db.derived else 0.1)
        self.stretch_s = float(stretch_s)
        self.rate = min(float(solve_fps), self.fps)
        self.inst = engine.solver_instances_
        self.lengths_s = self.inst.length / self.inst.fps
        self.min_window = int(np.ceil((float(self.lengths_s.min()) - self.stretch_s) * self.fps)) + 1
        self.mode = "path" if self.db.derived else "pose"
        self.sep = float(self.db.meta.get("hip_separation_m", 0.2))
        n_pts = 2 if self.db.derived else len(self.db.meta["control_joints"])
        self.cloud = np.zeros((0, n_pts, 3))
        self.path = np.zeros((0, 2))
        self.plan = _Plan()
        self.frame = 0  # target frames sent
        self.solves = 0
        self.solve_s: list[float] = []
        self._warm_up()

    def _warm_up(self) -> None:
        """Solve one window of the database's own control once and drop it: the compiled kernels
        load (~0.4 s in a fresh process) while the session opens, not when its first frames are due."""
        window = self.db.control[: 2 * self.min_window]
        if window.shape[0] >= self.min_window:
            self._solve(np.ascontiguousarray(window))

    @property
    def latency_s(self) -> float:
        return self.latency / self.fps

    @property
    def received(self) -> int:
        """Control frames received so far."""
        return int(self.cloud.shape[0])

    def hello_message(self) -> dict[str, Any]:
        """The first message: the target skeleton, rates, the latency and what to send."""
        sk = self.engine.target_motion(self.db.pairs[0][1])[0].skeleton
        return {
            "type": "skeleton",
            "names": list(sk.names),
            "parents": [int(p) for p in sk.parents],
            "offsets": np.round(sk.offsets, 5).tolist(),
            "fps": self.fps,
            "latency_s": self.latency_s,
            "latency_frames": self.latency,
            "control": self.mode,
            "control_joints": [] if self.db.derived else list(self.db.meta["control_joints"]),
            "rotation": "local quaternions (x, y, z, w); root position metres, Y up",
        }

    # ----------------------------------------------------------------------------------- input

    def push(self, frames: Array) -> dict[str, Any]:
        """Append control frames (at :attr:`fps`) and return the ``frames`` message of every target
        frame that became final (possibly none).

        ``frames``: ``(n, P, 3)`` the control joints' world positions (metres, Y up; in the order of
        ``control_joints``) for a motion database, or ``(n, 2)`` floor points ``[x, z]`` metres for
        a walk database (a path, e.g. from a game pad)."""
        arr = np.asarray(frames, dtype=np.float64)
        if arr.shape[0] > MAX_FRAMES_PER_MESSAGE:
            raise EngineError(f"at most {MAX_FRAMES_PER_MESSAGE} frames per message, got {arr.shape[0]}")
        if not np.all(np.isfinite(arr)):
            raise EngineError("control frames must be finite numbers")
        if self.mode == "path":
            if arr.ndim != 2 or arr.shape[1] != 2:
                raise EngineError("this walk database takes a path: frames are [x, z] floor points (metres)")
            self.path = np.concatenate((self.path, arr))
            self.cloud = self._path_cloud()
        else:
            p = self.cloud.shape[1]
            if arr.ndim != 3 or arr.shape[1:] != (p, 3):
                raise EngineError(
                    f"frames are [[x, y, z] x {p}] per frame (metres, Y up) for the joints "
                    f"{', '.join(self.db.meta['control_joints'])}"
                )
            self.cloud = np.concatenate((self.cloud, arr))
        return self._advance(final=False)

    def finish(self) -> dict[str, Any]:
        """The control has ended: plan to its last frame and return the remaining target frames."""
        return self._advance(final=True)

    def _path_cloud(self) -> Array:
        if self.path.shape[0] < 2:
            return floor_pair_cloud(self.path, np.zeros(self.path.shape[0]), self.sep)
        cloud, _ = trajectory_control(self.path, self.fps, self.sep, max_speed_m_s=1e9)
        return cloud

    # ---------------------------------------------------------------------------------- planning

    def _advance(self, final: bool) -> dict[str, Any]:
        n = self.received
        if final:
            while self.plan.reach < n and self._extend(n, n):
                pass
            if 0 < self.plan.reach < n:
                self._continue_last(n)
            return self._emit(self.plan.reach)
        frontier = n - self.latency  # target frames that must be sent now
        need = frontier + self.smooth  # every frame up to the frontier is final once the plan reaches this
        while self.plan.reach < need and self._extend(n, need):
            pass
        return self._emit(min(frontier, self.plan.reach - self.smooth))

    def _extend(self, n: int, need: int) -> bool:
        """Solve the window ``[plan reach, n)`` and commit its segments that start before ``need``
        (at least one). False when the window is too short to tile."""
        e = self.plan.reach
        if n - e < self.min_window:
            return False
        t0 = time.perf_counter()
        timed = self._solve(self.cloud[e:n])
        if timed is None:
            return False
        self.solve_s.append(time.perf_counter() - t0)
        self.solves += 1
        rows = self.db.instances[self.engine.kept_]
        for i, local in enumerate(timed.instances):
            a, b = int(timed.bounds[i]) + e, int(timed.bounds[i + 1]) + e
            if a >= need and i > 0:
                break
            pair, src, length = (int(v) for v in rows[int(local)])
            self._commit(pair, src, length, a, b, timed, i, int(local))
        return True

    def _commit(
        self, pair: int, src: int, length: int, a: int, b: int, timed: Timed, i: int, local: int
    ) -> None:
        self.plan.rows.append((pair, src, length))
        self.plan.start.append(a)
        self.plan.end.append(b)
        self.plan.align.append(
            (float(timed.cos[i]), float(timed.sin[i]), float(timed.tx[i]), float(timed.tz[i]))
        )
        self.plan.tail.append(self.inst.tails[local])

    def _continue_last(self, n: int) -> None:
        """Cover the last ``n - reach`` frames (shorter than any segment) by playing the last
        committed segment's source on, at its rate and alignment, within its clip."""
        pair, src, length = self.plan.rows[-1]
        a, b = self.plan.start[-1], self.plan.end[-1]
        extra = n - b
        src_extra = int(round(extra * length / max(b - a, 1)))
        last = int(self.db.offsets[pair + 1] - self.db.offsets[pair]) - 1
        start = min(src + length, last)
        self.plan.rows.append((pair, start, max(0, min(src_extra, last - start))))
        self.plan.start.append(b)
        self.plan.end.append(n)
        self.plan.align.append(self.plan.align[-1])
        self.plan.tail.append(self.plan.tail[-1])

    def _solve(self, window: Array) -> Timed | None:
        """The quick-beam DP of a window of control frames (database rate), re-timed at full rate;
        its first segment pays continuity against the last committed one. ``None`` when no sequence
        of segments tiles the window (a few more frames will make it possible)."""

        x = resample_cloud(window, self.fps, self.rate)
        cell_inst, cell_dur = legal_cells(self.lengths_s, self.rate, self.stretch_s, None)
        interp = interpretation(x, self.inst, cell_inst, cell_dur, self.rate)
        prev = self._previous_tail()
        kq = self.k / self.inst.tails.shape[1]
        if prev is not None:
            first = np.flatnonzero(cell_dur <= x.shape[0] - 1)
            ends = cell_dur[first]
            al = interp.alignment(first, ends)
            heads = align_points(self.inst.heads[cell_inst[first]], al[0], al[1], al[2], al[3])
            interp.D[first, ends] += kq * ((heads - prev[None]) ** 2).sum((1, 2))
        to_go = cost_to_go(interp.D, cell_dur)
        if not np.isfinite(to_go[0]):
            return None
        from .dp import typical_segment_cost

        try:
            res = solve(
                interp,
                self.inst,
                cell_inst,
                cell_dur,
                self.k,
                beam=QUICK_WIDTH * typical_segment_cost(interp.D),
                max_cells=QUICK_CELLS,
                to_go=to_go,
            )
        except Infeasible:
            res = solve(interp, self.inst, cell_inst, cell_dur, self.k, to_go=to_go)
        seq = cell_inst[res.cells]
        coarse = np.concatenate(([0], res.ends)) * (self.fps / self.rate)
        coarse[-1] = window.shape[0]
        return retime(
            window,
            self.inst,
            seq,
            coarse,
            self.k,
            self.fps,
            self.stretch_s,
            None,
            int(np.ceil(self.fps / self.rate)),
        )

    def _previous_tail(self) -> Array | None:
        """``(Q, 3)`` the last committed segment's target tail points, placed (or ``None``)."""
        if not self.plan.rows:
            return None
        c, s, tx, tz = self.plan.align[-1]
        tail = self.plan.tail[-1][None]
        placed = align_points(tail, np.array([c]), np.array([s]), np.array([tx]), np.array([tz]))
        return np.asarray(placed[0])

    # ---------------------------------------------------------------------------------- output

    def _emit(self, upto: int) -> dict[str, Any]:
        """The ``frames`` message of target frames ``[self.frame, upto)``."""
        start = self.frame
        if upto <= start or not self.plan.rows:
            return {"type": "frames", "start": start, "fps": self.fps, "root": [], "rotations": []}
        upto = min(upto, self.plan.reach)
        # assemble from the segment before the first new frame's (its cut is smoothed the same way
        # as when the frames before were sent) to the end of the plan
        ends = np.asarray(self.plan.end)
        first = int(np.searchsorted(ends, max(0, start - self.smooth - 1), side="right"))
        first = max(0, first - 1)
        a0 = self.plan.start[first]
        segs = slice(first, len(self.plan.rows))
        bounds = np.array([*self.plan.start[segs], self.plan.end[-1]], dtype=np.intp) - a0
        al = np.asarray(self.plan.align[segs])
        nseg = al.shape[0]
        timed = Timed(
            0.0,
            0.0,
            0.0,
            np.arange(nseg, dtype=np.intp),
            bounds,
            al[:, 0],
            al[:, 1],
            al[:, 2],
            al[:, 3],
            np.zeros(nseg),
            np.zeros(max(nseg - 1, 0)),
        )
        out = assemble(
            self.db,
            self.engine.target_motion,
            np.asarray(self.plan.rows[segs], dtype=np.intp).reshape(-1, 3),
            timed,
            int(bounds[-1]),
            self.fps,
            self.smooth / self.fps,
        )
        m = out.motion
        lo, hi = start - a0, upto - a0
        self.frame = upto
        return {
            "type": "frames",
            "start": start,
            "fps": self.fps,
            "root": np.round(m.root_positions[lo:hi] * m.metres_per_unit, 4).tolist(),
            "rotations": np.round(m.rotations[lo:hi], 5).tolist(),
        }
