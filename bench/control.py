"""Speed of the control-by-example engine: seconds of input per second of compute, with beam and exact.

Usage: ``python bench/control.py [--repeat N] [--held 07] [--solve-fps 7.5]`` from the project root
(needs ../shared/data; ``--solve-fps`` overrides the requests' downsampled rate, e.g. the paper's 7.5 Hz).

Two databases, as in Hsu et al. 2004 Sec. 6: the CMU salsa couples (13 pairs, the held-out dance's
leader drives the follower; beats segmentation) and Bandai-Namco dataset-2 walks (30 clips, derived
hip controls, footplant segmentation; a held-out walk's hip path drives it). For each, the figures:

* ``dp_*``: the paper's timing — the downsampled DP (interpretation distances for every cell and
  time + the forward pass), input seconds per compute second: ``quick`` (the first anytime stage, a
  narrow beam), ``beam`` (quick + the engine's default beam stage, width ``BEAM_WIDTH`` mean costs
  per segment of the quick solution), ``exact_exhaustive`` (no pruning at all, the paper's
  "without beam search") and ``exact_bnb`` (the optimum with pruning that cannot change it, given
  the beam's score);
* ``search_*``: the whole request (input parsing, DP, full-rate re-timing, assembly on the skeleton,
  smoothing, foot-skate cleanup) with ``exact: false`` (the beam schedule) and with the exact stage;
* ``beam_vs_exact``: relative excess of the beam's score over the exact optimum (goal <= 1%).

* ``cpu_x_realtime``: the same ratios from the median CPU time of this process (steadier than wall
  time on a shared machine: it leaves out the time other processes hold the cores);
* ``request_stages_cpu_ms``: median CPU milliseconds of each stage of a request (parse, interpret,
  quick DP, beam DP, re-time, assemble with clean-up, hand hold and quality report), and
  ``first_solution`` = parse + interpret + quick + re-time + assemble (what the first solution
  costs, the beam stage left out);
* ``first_solution_x_realtime``: input seconds per second from the request's start until the
  engine emits its first solution (parse -> interpret -> quick DP -> re-time -> assemble, foot
  clean-up, hand hold, quality report: the first complete answer a client receives), ``wall``
  (best of ``--repeat``) and ``cpu`` (median CPU time of this process), with ``first_solution_ms``
  (the same times in milliseconds; goal: >= 300x realtime);
* ``first_call_s``: the first DP call in a fresh process, compiling the numba kernel (empty cache)
  and loading it from ``__pycache__`` (the cost a fresh worker pays once).

Prints one JSON object. Timings are best-of ``--repeat`` (the machine is shared). The process is
set up as Segue's servers and workers are (:func:`motion.allocator.tune_process`: freed memory kept
for reuse, one BLAS thread).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits  # type: ignore[import-untyped]

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from engines.base import CollectingEmitter, Run, Solution  # noqa: E402
from engines.control.dp import (  # noqa: E402
    cost_to_go,
    interpretation,
    legal_cells,
    solve,
    typical_segment_cost,
)
from engines.control.engine import ControlEngine  # noqa: E402
from engines.control.points import resample_cloud  # noqa: E402
from engines.control.schedule import BEAM_CELLS, BEAM_WIDTH, QUICK_CELLS, QUICK_WIDTH  # noqa: E402
from engines.library import ClipInput, build_library, library_to_arrays  # noqa: E402
from engines.registry import parse_database_spec, parse_job_request  # noqa: E402
from motion.allocator import tune_process  # noqa: E402
from motion.bvh import parse_bvh  # noqa: E402
from motion.ground import ground_frames  # noqa: E402

DATA = ROOT.parent / "shared" / "data"


def engine_for(spec_data: dict[str, Any]) -> ControlEngine:
    spec = parse_database_spec(spec_data)
    clips = [ClipInput(c.display_name(), Path(str(c.bvh)).read_bytes(), c.units) for c in spec.clips]
    library = build_library(clips, spec.fps)
    arrays = ControlEngine.build(spec, library, CollectingEmitter(), lambda: False)
    arrays.update(library_to_arrays(library))
    return ControlEngine(library, arrays)


CPU: dict[str, float] = {}
"""Median CPU seconds (this process) of every timed step, by name, filled by :func:`best_of`."""


def best_of(repeat: int, fn: Any, name: str | None = None) -> tuple[float, Any]:
    """The best wall time of ``repeat`` runs of ``fn`` and its result; the median CPU time of the
    runs goes into :data:`CPU` under ``name`` (CPU time counts only this process's own work, so it
    is steadier than wall time on a shared machine)."""
    best, out, cpu = np.inf, None, []
    for _ in range(repeat):
        c0, t0 = time.process_time(), time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    if name is not None:
        CPU[name] = float(np.median(cpu))
    return best, out


def first_call_s() -> dict[str, float]:
    """Seconds of the first DP call in a fresh process: with an empty numba cache (compiling) and
    with the cache the package keeps in ``__pycache__`` (loading)."""
    code = (
        "import time, numpy as np;"
        "from engines.control.dp import Instances, interpretation, legal_cells, solve;"
        "c = np.random.default_rng(0).normal(size=(60, 3, 3)); s = np.arange(0, 50, 5);"
        "i = Instances(10.0, s, np.full(10, 5), c, c[s + 5], c[s]);"
        "ci, cd = legal_cells(i.length / 10.0, 10.0, 0.1, None); x = c[:30];"
        "it = interpretation(x, i, ci, cd, 10.0); t = time.perf_counter(); solve(it, i, ci, cd, 0.1);"
        "print(time.perf_counter() - t)"
    )
    out = {}
    with tempfile.TemporaryDirectory() as empty:
        for label, env in (("compile", {"NUMBA_CACHE_DIR": empty}), ("cached", {})):
            r = subprocess.run(
                [sys.executable, "-c", code],
                cwd=ROOT,
                env={**os.environ, **env},
                capture_output=True,
                text=True,
                check=True,
            )
            out[label] = round(float(r.stdout.strip().splitlines()[-1]), 3)
    return out


class FirstSolution(CollectingEmitter):
    """An emitter that notes the wall and CPU time of the first solution and then asks the engine
    to stop (:meth:`stop`, its ``should_stop``)."""

    def __init__(self) -> None:
        super().__init__()
        self.c0 = time.process_time()
        self.first: tuple[float, float] | None = None  # (wall s, CPU s) since the emitter was made

    def solution(self, solution: Solution) -> str:
        if self.first is None:
            self.first = (time.perf_counter() - self.t0, time.process_time() - self.c0)
        return super().solution(solution)

    def stop(self) -> bool:
        return self.first is not None


def first_solution(engine: ControlEngine, request: Any, input_s: float, repeat: int) -> dict[str, Any]:
    """Wall (best of ``repeat``) and CPU (median) time from the start of ``engine.search`` until its
    first solution is emitted, as milliseconds and as input seconds per second."""
    wall, cpu = [], []
    for _ in range(repeat):
        emit = FirstSolution()
        engine.search(request, Run(60.0, emit.stop, emit))
        if emit.first is None:
            raise RuntimeError("the engine emitted no solution")
        wall.append(emit.first[0])
        cpu.append(emit.first[1])
    t_wall, t_cpu = min(wall), float(np.median(cpu))
    return {
        "first_solution_x_realtime": {"wall": round(input_s / t_wall, 1), "cpu": round(input_s / t_cpu, 1)},
        "first_solution_ms": {"wall": round(1000 * t_wall, 2), "cpu": round(1000 * t_cpu, 2)},
    }


def stage_costs(engine: ControlEngine, request: Any, repeat: int) -> dict[str, float]:
    """Median CPU milliseconds of each stage of a request (the quick stage's solution): parse the
    control, interpret it (every cell and end time), the quick DP, the default beam stage, re-time
    at the full rate, assemble (with foot clean-up, hand hold and the quality report)."""
    steps: dict[str, Any] = {}
    t: dict[str, float] = {}

    def run(name: str, fn: Any) -> Any:
        best_of(repeat, fn, name)
        t[name] = round(CPU[name] * 1000, 2)
        return fn()

    ctl = run("parse", lambda: engine.control_cloud(request))
    pb = run("interpret", lambda: engine._interpret(request, ctl))
    res = run("quick", lambda: engine._solve_stage(pb, "quick", pb.d_unit, None, request, None))
    unit = res.score / max(1, res.cells.size)
    run("beam", lambda: engine._solve_stage(pb, "beam", unit, None, request, None))
    steps["timed"] = run(
        "retime",
        lambda: engine._retime(
            res, pb.x_full, pb.cell_inst, pb.cell_dur, pb.rate, request, pb.constraints, pb.window, pb.inst
        ),
    )
    run("assemble", lambda: engine._assembled(pb, ctl, res, steps["timed"], "quick", request, {}))
    t["first_solution"] = round(sum(t[k] for k in ("parse", "interpret", "quick", "retime", "assemble")), 2)
    return t


def measure(engine: ControlEngine, request: Any, input_s: float, repeat: int) -> dict[str, Any]:
    rate = float(request.solve_fps)
    inst = engine.solver_instances_
    ci, cd = legal_cells(inst.length / inst.fps, rate, request.stretch_s, request.stretch_ratio)
    ctl = engine.control_cloud(request)
    k = engine.continuity_weight(request)

    def prep() -> Any:
        x = resample_cloud(ctl.cloud, ctl.fps, rate)
        interp = interpretation(x, inst, ci, cd, rate)
        return interp, cost_to_go(interp.D, cd)

    out: dict[str, Any] = {"input_s": round(input_s, 2), "instances": int(inst.count), "cells": int(ci.size)}
    with threadpool_limits(limits=1):
        t_prep, (interp, to_go) = best_of(repeat, prep, "interpretation")
        d_unit = typical_segment_cost(interp.D)
        t_quick, quick = best_of(
            repeat,
            lambda: solve(
                interp, inst, ci, cd, k, beam=QUICK_WIDTH * d_unit, max_cells=QUICK_CELLS, to_go=to_go
            ),
            "quick",
        )
        unit = quick.score / len(quick.cells)
        t_beam1, beam = best_of(
            repeat,
            lambda: solve(interp, inst, ci, cd, k, beam=BEAM_WIDTH * unit, max_cells=BEAM_CELLS, to_go=to_go),
            "beam",
        )
        t_beam = t_quick + t_beam1
        t_exh, exh = best_of(1, lambda: solve(interp, inst, ci, cd, k), "exhaustive")
        t_bnb, bnb = best_of(
            repeat, lambda: solve(interp, inst, ci, cd, k, upper_bound=beam.score, to_go=to_go), "bnb"
        )
    out.update(
        dp_beam_x_realtime=round(input_s / (t_prep + t_beam), 1),
        dp_exact_exhaustive_x_realtime=round(input_s / (t_prep + t_exh), 1),
        dp_exact_bnb_x_realtime=round(input_s / (t_prep + t_beam + t_bnb), 1),
        dp_quick_x_realtime=round(input_s / (t_prep + t_quick), 1),
        dp_seconds={
            "interpretation": round(t_prep, 4),
            "quick": round(t_quick, 4),
            "beam": round(t_beam1, 4),
            "exhaustive": round(t_exh, 4),
            "bnb_after_beam": round(t_bnb, 4),
        },
        beam_vs_exact=round((beam.score - exh.score) / exh.score, 5),
        quick_vs_exact=round((quick.score - exh.score) / exh.score, 5),
        bnb_equals_exhaustive=bool(abs(bnb.score - exh.score) <= 1e-9 * abs(exh.score)),
    )
    fast = request.model_copy(update={"exact": False})
    fast.attach_inputs(dict(request._inputs))
    t_search, _ = best_of(
        repeat, lambda: engine.search(fast, Run(60.0, emit=CollectingEmitter())), "search_beam"
    )
    t_full, _ = best_of(
        repeat, lambda: engine.search(request, Run(60.0, emit=CollectingEmitter())), "search_exact"
    )
    out.update(
        search_beam_x_realtime=round(input_s / t_search, 1),
        search_exact_x_realtime=round(input_s / t_full, 1),
    )
    c = CPU
    out["cpu_x_realtime"] = {
        "dp_quick": round(input_s / (c["interpretation"] + c["quick"]), 1),
        "dp_beam": round(input_s / (c["interpretation"] + c["quick"] + c["beam"]), 1),
        "dp_exact_exhaustive": round(input_s / (c["interpretation"] + c["exhaustive"]), 1),
        "dp_exact_bnb": round(input_s / (c["interpretation"] + c["quick"] + c["beam"] + c["bnb"]), 1),
        "search_beam": round(input_s / c["search_beam"], 1),
        "search_exact": round(input_s / c["search_exact"], 1),
    }
    out.update(first_solution(engine, fast, input_s, repeat))
    with threadpool_limits(limits=1):
        out["request_stages_cpu_ms"] = stage_costs(engine, fast, repeat)
    return out


def salsa(held: str, repeat: int, solve_fps: float | None = None) -> dict[str, Any]:
    s = DATA / "cmu-salsa"
    trials = sorted({f.name[3:5] for f in s.glob("60_*_scaled.bvh")})
    engine = engine_for(
        {
            "kind": "control",
            "pairs": [
                {"control": str(s / f"60_{t}_scaled.bvh"), "target": str(s / f"61_{t}_scaled.bvh")}
                for t in trials
                if t != held
            ],
            "segmentation": {"method": "beats", "beats_per_segment": 2},
        }
    )
    lead = s / f"60_{held}_scaled.bvh"
    extra = {} if solve_fps is None else {"solve_fps": solve_fps}
    request = parse_job_request({"engine": "control", "control": {"bvh": "lead.bvh"}, **extra})
    request.attach_inputs({"lead.bvh": lead.read_bytes()})
    motion = parse_bvh(lead.read_bytes())
    return {"database": f"cmu-salsa minus {held}", **measure(engine, request, motion.duration_s, repeat)}


def walks(repeat: int, solve_fps: float | None = None) -> dict[str, Any]:
    b = DATA / "bandai-namco" / "dataset-2"
    train = [
        b / f"dataset-2_{kind}_normal_{i:03d}.bvh"
        for kind in ("walk", "walk-turn-left", "walk-turn-right")
        for i in range(1, 11)
    ]
    engine = engine_for(
        {
            "kind": "control",
            "pairs": [{"target": str(p)} for p in train],
            "segmentation": {"method": "footplants"},
        }
    )
    held = parse_bvh((b / "dataset-2_walk_normal_012.bvh").read_bytes()).to_units("m")
    path, _ = ground_frames(held)
    extra = {} if solve_fps is None else {"solve_fps": solve_fps}
    request = parse_job_request(
        {"engine": "control", "control": {"trajectory": {"fps": held.fps, "points": path.tolist()}}, **extra}
    )
    return {
        "database": "bandai dataset-2 walks (30 clips)",
        **measure(engine, request, held.duration_s, repeat),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--held", default="07", help="held-out salsa trial")
    parser.add_argument(
        "--solve-fps",
        type=float,
        default=None,
        help="rate of the downsampled solve (default: the request's 10)",
    )
    args = parser.parse_args()
    tune_process()  # as in every Segue server and worker (see motion/allocator.py)
    if args.solve_fps is not None and args.solve_fps <= 0:
        parser.error("--solve-fps must be positive")
    if not DATA.exists():
        print(json.dumps({"skipped": f"no shared data at {DATA}"}))
        return
    print(
        json.dumps(
            {
                "solve_fps": 10.0 if args.solve_fps is None else args.solve_fps,
                "salsa": salsa(args.held, args.repeat, args.solve_fps),
                "walk": walks(args.repeat, args.solve_fps),
                "first_call_s": first_call_s(),
                "load_avg": [round(x, 2) for x in os.getloadavg()],
            }
        )
    )


if __name__ == "__main__":
    main()
