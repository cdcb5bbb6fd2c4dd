"""Compile the control engine's kernels before the first request needs them (``segue warm``).

The control engine's DP, alignment and re-timing kernels and :mod:`motion.compiled` are compiled
by numba with ``cache=True`` and kept in numba's cache (:func:`motion.jitcache.cache_dir`). A
process that was not warmed compiles only what a request cannot do without -- the forward DP
pass and the motion kernels, about 6 CPU-s with an empty cache -- and runs exact NumPy twins of
the secondary kernels (:mod:`engines.control.tier`). :func:`warm` pays every compile off the
request path: it switches this process to the compiled kernels, runs two tiny control requests
on bundled samples (a salsa pair driven by a leader's motion, and walks driven by a floor
trajectory), which call every kernel with the argument types real requests use, then leaves a
stamp in the cache (:func:`stamp`): processes that find it run the compiled kernels, and later
warms return at once (numba would only load the code, but the two tiny requests still cost ~3
CPU-s). ``segue warm``, ``segue serve`` and ``segue worker`` run it (the server in a background
process, a worker before its first job); the Docker image runs it at build time.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from motion import parse_bvh
from motion.bvh import bvh_text
from motion.samples import resolve_path
from schemas.control import ControlDatabaseSpec, ControlRequest

from ..base import CollectingEmitter, Run
from ..library import ClipInput, build_library, library_to_arrays
from . import tier
from .engine import ControlEngine

Say = Callable[[str], None]


def _clip(ref: str, start: int, end: int, name: str) -> ClipInput:
    """Frames ``[start, end)`` of a bundled sample as a BVH clip named ``name``."""
    motion = parse_bvh(resolve_path(ref).read_bytes(), source=ref)
    return ClipInput(name, bvh_text(motion.slice(start, min(end, motion.num_frames))).encode())


def _engine(spec_data: dict[str, object], clips: list[ClipInput]) -> ControlEngine:
    spec = ControlDatabaseSpec.model_validate(spec_data)
    library = build_library(clips, spec.fps)
    arrays = ControlEngine.build(spec, library, CollectingEmitter(), lambda: False)
    arrays.update(library_to_arrays(library))
    return ControlEngine(library, arrays)


def salsa_request() -> tuple[ControlEngine, ControlRequest]:
    """The warm-up's salsa request: a database of one bundled pair (leader 02 and its follower,
    12 s at 60 fps, two beats a segment) and 6 s of that leader as the control; the engine and the
    parsed request (tests run it in both tiers, :mod:`engines.control.tier`)."""
    lead = _clip("sample:salsa-leader-02", 0, 720, "lead")
    follow = _clip("sample:salsa-follower-02", 0, 720, "follow")
    engine = _engine(
        {
            "kind": "control",
            "pairs": [{"control": "lead", "target": "follow"}],
            "clips": [{"bvh": "lead.bvh", "name": "lead"}, {"bvh": "follow.bvh", "name": "follow"}],
            "segmentation": {"method": "beats", "beats_per_segment": 2},
        },
        [lead, follow],
    )
    request = ControlRequest.model_validate(
        {"engine": "control", "control": {"bvh": "control.bvh"}, "budget_s": 600}
    )
    request._inputs["control.bvh"] = _clip("sample:salsa-leader-02", 120, 480, "control").data
    return engine, request


def _salsa() -> None:
    engine, request = salsa_request()
    engine.search(request, Run(request.budget_s))


def _walk() -> None:
    clips = [_clip("sample:walk-05-01", 0, 400, "walk")]
    engine = _engine(
        {
            "kind": "control",
            "fps": 30,
            "pairs": [{"target": "walk"}],
            "clips": [{"bvh": "walk.bvh", "name": "walk"}],
            "segmentation": {"method": "footplants"},
        },
        clips,
    )
    t = np.arange(90) / 30.0
    points = [[float(1.2 * s), float(0.3 * np.sin(s))] for s in t]
    request = ControlRequest.model_validate(
        {"engine": "control", "control": {"trajectory": {"fps": 30, "points": points}}, "budget_s": 600}
    )
    engine.search(request, Run(request.budget_s))


def _layouts() -> None:
    """:func:`motion.compiled.sample_into` with a clip's rotations in C and in Fortran order
    (clips come in either, each a specialisation of the kernel)."""
    from dataclasses import replace

    from motion.compiled import sample_into

    motion = parse_bvh(resolve_path("sample:walk").read_bytes(), source="sample:walk").slice(0, 20)
    j, k = motion.skeleton.num_joints, motion.joint_translations.shape[1]
    for q in (np.ascontiguousarray(motion.rotations), np.asfortranarray(motion.rotations)):
        m = replace(motion, rotations=q)
        frames = np.linspace(0.0, 19.0, 8)
        root, rot, jt = np.empty((8, 3)), np.empty((8, j, 4)), np.empty((8, max(k, 0), 3))
        sample_into(m, frames, np.arange(8), root, rot, jt)


def stamp() -> Path:
    """The file that says this cache holds the kernels of these sources
    (:func:`engines.control.tier.stamp`)."""
    return tier.stamp()


def warm(say: Say | None = None, force: bool = False) -> float:
    """Compile (or load from numba's cache) every kernel a control request runs; returns the
    seconds it took. Once done for these sources and this cache (:func:`stamp`), it returns at
    once unless ``force``. ``say`` gets one line before and one after."""
    t0 = time.perf_counter()
    done = stamp()
    if done.exists() and not force:
        if say is not None:
            say(f"compiled kernels ready (numba cache {done.parent})")
        return time.perf_counter() - t0
    if say is not None:
        say("compiling the control kernels (once per install: about 15 s of CPU)")
    tier.use_compiled()  # the requests below run (and so compile) every compiled kernel
    _salsa()
    _walk()
    _layouts()
    with contextlib.suppress(OSError):  # a read-only cache: warm again next time, no harm
        done.parent.mkdir(parents=True, exist_ok=True)
        done.write_text(f"{time.time()}\n", encoding="utf-8")
    elapsed = time.perf_counter() - t0
    if say is not None:
        say(f"compiled kernels ready in {elapsed:.1f} s (numba cache {done.parent})")
    return elapsed
