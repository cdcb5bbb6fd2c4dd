"""Work budgets: what a synthesis request will cost, estimated before it is queued.

:func:`estimate_work` reads a validated request and facts of its database (rate, joints) and gives
the output length (frames per character), the number of characters, ``joint_frames`` = characters x
frames x joints (what every engine's output arrays and most of its working arrays scale with), a
memory estimate and a compute-time estimate. :func:`check_work` compares them with
:class:`WorkLimits` (the API's ``SEGUE_MAX_*`` settings) and returns the problems, each naming the
number and its limit, so the API refuses the request at submission (413) instead of a worker
running out of memory or time.

The per-joint-frame constants are measured on this project's engines (CMU salsa, 120 fps, 38
joints: a rhythm crowd of 40 characters x 20 s peaks at 1.1 GB and takes 11 s on one core; a
single 1000-s dance 1.8 GB and 18 s) and rounded up; :func:`expected_frames` is also what a
worker compares the result with, so a result shorter than asked is flagged instead of silently
``done``.

Input files count from their headers and capped counts (:mod:`workers.input_facts`): a MIDI song's
length and beats (at most :data:`~workers.input_facts.MAX_MIDI_EVENTS` events read), a recording's
length and decoded size (``soundfile.info``), a control BVH's frames (its header); so a request's
size is known at submission whatever its files hold, in bounded time and memory.
"""

from __future__ import annotations

import threading
from dataclasses import asdict, dataclass
from typing import Any

from cachetools import LRUCache, cached

from engines.base import DatabaseFacts
from engines.registry import engine_class, parse_job_request
from schemas.bases import JobRequestBase

BASE_MEMORY_BYTES = 300 * 1024 * 1024
"""A worker process with the engines loaded (numpy, scipy, scikit-learn) and a database."""
SECONDS_PER_JOINT_FRAME = 4e-6
"""Compute per output joint-frame after the search budget (assembly, blending, foot clean-up)."""


@dataclass(frozen=True, slots=True)
class WorkLimits:
    """The most one job may ask for (``None``: no limit on that quantity)."""

    max_output_frames: int | None = 36_000
    max_joint_frames: int | None = 10_000_000
    max_memory_bytes: int | None = 4 << 30
    max_budget_s: float | None = 600.0


@dataclass(frozen=True, slots=True)
class WorkEstimate:
    """What a request will cost. ``frames`` is per character at the output rate (None: unknown);
    ``characters`` counts every output motion (dancers, both partners of a couple, alternatives)."""

    frames: int | None
    characters: int
    joints: int
    fps: float
    joint_frames: int | None
    memory_bytes: int | None
    seconds: float
    problems: tuple[str, ...] = ()
    """What the input files alone exceed (too many MIDI events, an implausible tempo...)."""

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


def expected_frames(request: JobRequestBase, facts: DatabaseFacts) -> int | None:
    """Output frames per character that ``request`` asks for at the output rate (None: unknown),
    as its engine estimates them (:meth:`engines.base.Engine.estimate`)."""
    return engine_class(request.engine).estimate(request, facts).frames


def estimate_work(request: JobRequestBase, facts: DatabaseFacts) -> WorkEstimate:
    """The cost of a validated request against a database with ``facts`` (rate, joints, clips):
    its engine's estimate of the output, plus what its input files add (headers and capped
    counts only, so bounded whatever the files hold)."""
    out = engine_class(request.engine).estimate(request, facts)
    joints = facts.joints
    budget = float(request.budget_s)
    if out.frames is None:
        return WorkEstimate(None, out.characters, joints, out.fps, None, None, budget, out.problems)
    joint_frames = out.characters * out.frames * max(joints, 1)
    memory = BASE_MEMORY_BYTES + joint_frames * out.bytes_per_joint_frame + out.input_bytes
    seconds = budget + joint_frames * SECONDS_PER_JOINT_FRAME
    return WorkEstimate(
        out.frames, out.characters, joints, out.fps, joint_frames, memory, round(seconds, 3), out.problems
    )


def check_work(work: WorkEstimate, limits: WorkLimits) -> list[str]:
    """Every limit ``work`` exceeds, as a sentence naming the number and the limit."""
    problems = list(work.problems)
    if limits.max_budget_s is not None and work.seconds > limits.max_budget_s:
        problems.append(
            f"the job would take about {work.seconds:.0f} s (budget_s plus assembly), over the "
            f"{limits.max_budget_s:g}-s limit (SEGUE_MAX_JOB_SECONDS)"
        )
    if (
        work.frames is not None
        and limits.max_output_frames is not None
        and work.frames > limits.max_output_frames
    ):
        problems.append(
            f"{work.frames} output frames per character at {work.fps:g} fps is over the limit of "
            f"{limits.max_output_frames} (SEGUE_MAX_OUTPUT_FRAMES)"
        )
    jf, max_jf = work.joint_frames, limits.max_joint_frames
    if jf is not None and max_jf is not None and jf > max_jf:
        problems.append(
            f"{work.characters} character(s) x {work.frames} frames x {work.joints} joints = "
            f"{jf} joint-frames is over the limit of {max_jf} (SEGUE_MAX_JOINT_FRAMES)"
        )
    memory, max_memory = work.memory_bytes, limits.max_memory_bytes
    if memory is not None and max_memory is not None and memory > max_memory:
        problems.append(
            f"the job would need about {memory / 2**20:.0f} MiB, over the "
            f"{max_memory / 2**20:.0f}-MiB limit (SEGUE_MAX_JOB_MEMORY_MB)"
        )
    return problems


@cached(LRUCache(maxsize=256), key=lambda store, db_id: (store.url, db_id), lock=threading.Lock())
def database_facts(store: Any, db_id: str) -> DatabaseFacts:
    """Read the facts from a database of ``store`` (a :class:`~workers.store.Store`; only the small
    arrays are read; a built database never changes, so the last 256 are kept)."""
    with store.open_database(db_id) as z:
        names = [str(n) for n in z["library.names"]]
        counts = [int(c) for c in z["library.frame_counts"]]
        fps = float(z["library.fps"])
        joints = int(z["library.offsets"].shape[1])
        joint_names = (
            tuple(str(n) for n in z["library.skeleton.names"]) if "library.skeleton.names" in z else ()
        )
    return DatabaseFacts(fps, joints, dict(zip(names, counts, strict=True)), joint_names)


SHORT_FRACTION = 0.95
"""A result with fewer than this fraction of the frames asked for is flagged as short."""


def shortfall(store: Any, job_id: str, payload: dict[str, Any], result: str | None) -> dict[str, Any] | None:
    """``{"frames", "requested_frames"}`` when a synthesis job's result is shorter than asked
    (below :data:`SHORT_FRACTION`), else None. Read by the owner of a job before it relays ``done``,
    so a short result says so in its terminal event."""
    request_data = payload.get("request")
    if result is None or not isinstance(request_data, dict):
        return None
    try:
        request = parse_job_request(request_data)
        if request.database is None:
            return None
        facts = database_facts(store, request.database)
        wanted = expected_frames(request, facts)
        got = store.result_report(job_id, result).frames
    except Exception:  # a flag is a courtesy: never fail a finished job over it
        return None
    if wanted is None or got is None or got >= SHORT_FRACTION * wanted:
        return None
    return {"frames": int(got), "requested_frames": int(wanted)}


def database_frames(clips: list[tuple[int, float]], fps: float | None) -> int:
    """Frames of a database at its rate: ``clips`` are (frames, fps) of its clips; ``fps`` the rate
    the spec resamples them to (None: each keeps its own)."""
    return sum(round(frames * (fps / clip_fps if fps else 1.0)) for frames, clip_fps in clips)
