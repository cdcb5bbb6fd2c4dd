"""The clip engine: an excerpt of a database clip, optionally mirrored and placed on the floor.

The smallest real engine: it answers at once with one solution whose provenance is exact. It
previews clips (the browser's library view) and is the minimal end-to-end job of the runtime.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from motion import MotionError
from motion import rotations as rot
from motion.ground import body_root, heading
from motion.mirror import mirror
from schemas.databases import ClipsDatabaseSpec
from schemas.jobs import ClipRequest

from .base import DatabaseFacts, Engine, EngineError, OutputEstimate, Run, Solution, Stopped


class ClipEngine(Engine[ClipRequest, ClipsDatabaseSpec]):
    """Excerpts of clips (request: :class:`schemas.jobs.ClipRequest`)."""

    name = "clip"
    kind = "clips"
    request_model = ClipRequest
    spec_model = ClipsDatabaseSpec

    @classmethod
    def estimate(cls, request: ClipRequest, facts: DatabaseFacts) -> OutputEstimate:
        """The excerpt's frames (known from the clip's length when ``end`` is left out)."""
        total = facts.clip_frames.get(request.clip)
        end = request.end if request.end is not None else total
        frames = None if end is None else max(0, min(end, total or end) - request.start)
        return OutputEstimate(frames, 1, facts.fps, 200)

    def search(self, request: ClipRequest, run: Run) -> Stopped:
        try:
            source = self.library.clip(request.clip)
        except MotionError as exc:
            raise EngineError(str(exc)) from None
        end = source.num_frames if request.end is None else request.end
        if request.start >= source.num_frames or end > source.num_frames:
            raise EngineError(
                f"frames {request.start}:{end} are outside clip {request.clip!r} ({source.num_frames} frames)"
            )
        motion = source.slice(request.start, end)
        if request.mirror:
            motion = mirror(motion)
        if request.position is not None or request.heading_deg is not None:
            pos = motion.global_positions()
            yaw0 = float(heading(motion, pos)[0])
            target_yaw = yaw0 if request.heading_deg is None else np.radians(request.heading_deg)
            turn = rot.from_yaw(np.float64(target_yaw - yaw0))
            start_xz = pos[0, body_root(motion.skeleton), [0, 2]]  # the body, not a static joint 0
            goal_xz = start_xz if request.position is None else np.asarray(request.position, dtype=np.float64)
            rel = motion.root_positions - np.array([start_xz[0], 0.0, start_xz[1]])
            root = rot.rotate(turn, rel) + np.array([goal_xz[0], 0.0, goal_xz[1]])
            q = motion.rotations.copy()
            q[:, 0] = rot.multiply(turn, q[:, 0])
            motion = replace(motion, root_positions=root, rotations=q)
        provenance = [(request.clip, f) for f in range(request.start, end)]
        run.emit.solution(Solution(motion=motion, score=0.0, terms={"excerpt": 0.0}, provenance=provenance))
        return Stopped.work
