"""A scripted anytime engine for runtime tests (loaded with SEGUE_ENGINE_PLUGINS).

It optionally keeps the CPU busy for ``spin_s`` first (an engine that ignores cancels), then improves
its score ``steps`` times, ``step_s`` seconds apart, polling ``should_stop`` between steps, so tests
can observe solutions arriving, cancel mid-search, or kill a worker mid-job. With ``hold_after`` it
stops improving after that many solutions and waits (polling ``should_stop``, within ``budget_s``)
for a cancel: a test that cancels after seeing them then knows exactly which solutions exist,
however long the cancel takes to arrive on a loaded machine. With ``go_file`` it waits (the same
way) until that file exists before its first step: a test can kill it mid-job at its leisure. Each
solution is a real excerpt of the database's first clip (10 + i frames), so results download.

The ``held`` database kind (engine ``held``) builds like ``clips`` but, like a long real build,
reports progress every ``tick_s`` until ``go_file`` exists (polling ``should_stop``): a test can
kill a worker in the middle of a build that keeps talking to it.
"""

from __future__ import annotations

import os
import time
from typing import Literal

from pydantic import Field

from engines.base import Arrays, Emitter, Engine, EngineError, Run, ShouldStop, Solution, Stopped
from engines.library import MotionLibrary
from engines.registry import register
from schemas.bases import DatabaseSpecBase, JobRequestBase
from schemas.databases import ClipsDatabaseSpec


class ScriptedRequest(JobRequestBase):
    engine: Literal["scripted"] = "scripted"
    steps: int = Field(default=5, ge=1, le=1000)
    step_s: float = Field(default=0.1, ge=0, le=60)
    fail_at: int | None = Field(default=None, description="raise an engine error at this step")
    input: str | None = Field(default=None, description="an input file; its size becomes a score term")
    frames: int | None = Field(
        default=None, ge=1, le=100_000, description="frames asked for (each solution has 10 + i frames)"
    )
    hold_after: int | None = Field(
        default=None, ge=1, description="after this many solutions, wait for a cancel (within budget_s)"
    )
    go_file: str | None = Field(
        default=None, description="wait until this file exists (within budget_s) before the first step"
    )
    spin_s: float = Field(
        default=0.0, ge=0, le=60, description="busy the CPU (holding the GIL, not polling should_stop) first"
    )

    def input_files(self) -> list[str]:
        return [self.input] if self.input else []


@register
class ScriptedEngine(Engine[ScriptedRequest, ClipsDatabaseSpec]):
    name = "scripted"
    kind = "clips"
    request_model = ScriptedRequest
    spec_model = ClipsDatabaseSpec

    def search(self, request: ScriptedRequest, run: Run) -> Stopped:
        budget_s, emit, should_stop = run.budget_s, run.emit, run.should_stop
        clip = self.library.motions[0]
        name = self.library.names[0]
        t0 = time.monotonic()
        extra = {"input_bytes": float(len(request.input_bytes(request.input)))} if request.input else {}
        spin_until = time.monotonic() + request.spin_s
        while time.monotonic() < spin_until:
            sum(range(10_000))  # an engine busy in Python: ignores cancels and holds the GIL
        t0 = time.monotonic()
        while request.go_file is not None and not os.path.exists(request.go_file):
            if should_stop():
                return Stopped.cancelled
            if time.monotonic() - t0 > budget_s:
                return Stopped.budget
            time.sleep(0.01)
        for i in range(request.steps):
            if should_stop():
                return Stopped.cancelled
            if time.monotonic() - t0 > budget_s:
                return Stopped.budget
            if request.hold_after is not None and i >= request.hold_after:
                while not should_stop():
                    if time.monotonic() - t0 > budget_s:
                        return Stopped.budget
                    time.sleep(0.01)
                return Stopped.cancelled
            if request.fail_at == i:
                raise EngineError(f"scripted failure at step {i}")
            time.sleep(request.step_s)
            n = min(10 + i, clip.num_frames)
            emit.solution(
                Solution(
                    motion=clip.slice(0, n),
                    score=float(request.steps - i),
                    terms={"remaining": float(request.steps - i), **extra},
                    provenance=[(name, f) for f in range(n)],
                )
            )
        return Stopped.work


class HeldSpec(DatabaseSpecBase):
    """A clips database whose build reports progress until ``go_file`` exists."""

    kind: Literal["held"] = "held"
    go_file: str = Field(description="the build ends once this file exists")
    tick_s: float = Field(default=0.01, gt=0, le=10, description="seconds between progress events")


class HeldRequest(JobRequestBase):
    engine: Literal["held"] = "held"


@register
class HeldEngine(Engine[HeldRequest, HeldSpec]):
    name = "held"
    kind = "held"
    request_model = HeldRequest
    spec_model = HeldSpec

    @classmethod
    def build(cls, spec: HeldSpec, library: MotionLibrary, emit: Emitter, should_stop: ShouldStop) -> Arrays:
        ticks = 0
        while not os.path.exists(spec.go_file):
            if should_stop():
                raise InterruptedError("build cancelled")
            ticks += 1
            emit.progress(0.5, f"held build: tick {ticks}")
            time.sleep(spec.tick_s)
        return {}

    def search(self, request: HeldRequest, run: Run) -> Stopped:
        raise EngineError("the held engine only builds")
