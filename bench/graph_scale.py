"""Benchmark: graph databases from 10k to 1M frames (build, memory, disk, search), one JSON line per size.

Needs ``../shared/data/bandai-namco``. The library of a size is made of every clip of both sets (639
clips, 85,981 frames at 30 fps, one skeleton) and, past that, copies: variant ``v`` of the sequence
``mirrored``, ``x0.9``, ``mirrored x0.9``, ``x1.1``, ``mirrored x1.1``, ``x0.8``, ... (left/right
mirror image by ``motion.mirror``, every copy with the joint frames of
``motion.mirror.joint_frames`` over all the clips, as a graph spec's ``mirror`` does; time-scaled =
played at that speed, resampled to 30 fps), clip by clip until the size is reached. Sizes below the
data take an evenly spread subset of the clips (every k-th clip). Each size is built in a fresh
process (so ``peak_rss_build_mb`` is its own) doing what a worker does
(``workers.execute.build_database_bytes``: the graph build, the library arrays with the engine's
replacing them, quality reference and foot floor); ``disk_mb`` is the size of
``workers.store.npz_bytes``. Another fresh process loads it into an engine and answers a
``--seconds`` (20) request from the origin to a body goal ``--goal`` (12) m away (heading 90), once
per ``--seeds`` seed, bounded by the request's rounds (15), like any request:

* ``first_solution_s`` / ``_cpu_s``: wall and process-CPU time to the first solution;
* ``round_s`` / ``round_cpu_s``: the rest of the search (chain seeds and rounds) per round;
* ``goal_error_cm`` and ``ok``: the best result's distance to the goal and quality verdict (every
  seed's in ``seeds``).

``build_cpu_s`` is the build's process CPU time (all threads), ``build_s`` its wall time. With
``--eighth`` every 8th clip of each size's library is built too and ``cpu_exponent`` is the growth
exponent of the build CPU between the two. With ``--keep DIR`` the databases stay in ``DIR``
(``graph-<size>.npz`` and the build figures beside it) and ``--reuse`` searches them again
without building. With ``--recall`` (sizes up to 40k) the all-pairs build runs too and
``edge_recall`` is the fraction of its leaf edges the indexed build keeps, ``best_edge_recall``
the fraction of frames whose cheapest all-pairs edge it keeps. ``build_load_avg`` and
``search_load_avg`` are the 1-minute load averages at the start (other work on a shared machine
slows the wall times down: the CPU times move less).

Run the big sizes with ``nice -n 10``, one at a time: ``nice -n 10 python bench/graph_scale.py
--sizes 1000000 --keep /tmp/graphscale``.
"""

from __future__ import annotations

import argparse
import glob
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

DATA = ROOT.parent / "shared" / "data" / "bandai-namco"
SPEEDS = (1.0, 0.9, 1.1, 0.8, 1.2, 0.85, 1.15, 0.95, 1.05, 0.75, 1.25, 0.7, 1.3)


def variants() -> list[tuple[bool, float]]:
    """(mirrored, speed) of the copies, in order: the data itself first."""
    return [(m, s) for s in SPEEDS for m in (False, True)]


def library_of(frames: int) -> tuple[Any, str]:
    """A library of about ``frames`` frames (module docstring) and a description of it."""
    from engines.library import ClipInput, MotionLibrary, build_library
    from motion.mirror import joint_frames, mirror
    from motion.resample import resample

    files = sorted(glob.glob(str(DATA / "dataset-1" / "*.bvh"))) + sorted(
        glob.glob(str(DATA / "dataset-2" / "*.bvh"))
    )
    base = build_library([ClipInput(Path(f).stem, Path(f).read_bytes()) for f in files], fps=30.0)
    total = base.total_frames
    if frames < total:
        k = max(1, round(total / frames))  # an evenly spread subset: every k-th clip
        pick = list(range(0, len(files), k))
        names, motions, labels = [], [], []
        for i in pick:
            names.append(base.names[i])
            motions.append(base.motions[i])
            labels.append(base.labels[i])
        return MotionLibrary(tuple(names), tuple(motions), tuple(labels)), f"every {k}th Bandai-Namco clip"
    names, motions = list(base.names), list(base.motions)
    conventions = joint_frames(base.motions)  # one convention for every mirror image
    count = total
    used: list[str] = []
    for mirrored, speed in variants()[1:]:
        if count >= frames:
            break
        tag = ("mirrored " if mirrored else "") + (f"x{speed:g}" if speed != 1.0 else "")
        used.append(tag.strip())
        for name, m in zip(base.names, base.motions, strict=True):
            if count >= frames:
                break
            c = mirror(m, conventions) if mirrored else m
            if speed != 1.0:
                c = resample(replace(c, fps=c.fps * speed), 30.0)
            names.append(f"{name} ({tag.strip()})")
            motions.append(replace(c, name=names[-1]))
            count += c.num_frames
    lib = MotionLibrary(tuple(names), tuple(motions), tuple(() for _ in names))
    return lib, "Bandai-Namco (both sets) + copies: " + ", ".join(used)


def rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def recall(library: Any, arrays: dict[str, Any]) -> dict[str, float]:
    from engines.base import CollectingEmitter
    from engines.graph.build import build_graph
    from engines.graph.model import EdgeTree
    from engines.registry import parse_database_spec

    spec = parse_database_spec({"kind": "graph", "clips": [{"bvh": "x.bvh"}], "candidates": "all_pairs"})
    exact = build_graph(spec, library, CollectingEmitter(), lambda: False)

    def leaves(a: dict[str, Any]) -> tuple[np.ndarray, np.ndarray]:
        t = EdgeTree.from_arrays(a)
        m = t.is_leaf
        # int64: the stored tree is int32
        fc, ff, tc, tf = (x[m].astype(np.int64) for x in (t.from_clip, t.from_frame, t.to_clip, t.to_frame))
        key = ((fc * 100000 + ff) * 10000 + tc) * 100000 + tf
        return key, t.cost[m]

    got, _ = leaves(arrays)
    want, cost = leaves(exact)
    hit = np.isin(want, got)
    t = EdgeTree.from_arrays(exact)
    m = t.is_leaf
    frame = t.from_clip[m].astype(np.int64) * 100000 + t.from_frame[m]
    order = np.lexsort((cost, frame))
    first = np.concatenate(([True], np.diff(frame[order]) != 0))
    return {
        "exact_leaf_edges": int(want.size),
        "edge_recall": round(float(hit.mean()), 4),
        "best_edge_recall": round(float(hit[order][first].mean()), 4),
    }


def build_arrays(library: Any, candidates: str) -> tuple[dict[str, Any], dict[str, Any]]:
    """What ``workers.execute.build_database_bytes`` stores for the library (in its order), and the
    build's figures (CPU over all threads, wall)."""
    from engines.base import CollectingEmitter
    from engines.graph.engine import GraphEngine
    from engines.registry import parse_database_spec

    spec = parse_database_spec({"kind": "graph", "clips": [{"bvh": "x.bvh"}], "candidates": candidates})
    c0, t0 = time.process_time(), time.perf_counter()
    arrays = GraphEngine.library_arrays(spec, library, CollectingEmitter(), lambda: False)
    build_cpu, build_s = time.process_time() - c0, time.perf_counter() - t0
    report = json.loads(str(arrays["graph.report"]))
    figures: dict[str, Any] = {
        "frames": library.total_frames,
        "clips": len(library.names),
        "candidates": report["candidates"],
        "build_cpu_s": round(build_cpu, 1),
        "build_s": round(build_s, 1),
        "scan_s": report["scan_s"],
        "leaf_edges": report["leaf_edges"],
        "tree_nodes": report["tree_nodes"],
        "index_cells": report.get("index_cells"),
        "dropped_clips": len(report["dropped_clips"]),
        "dropped_frames": report.get("dropped_frames"),
    }
    return arrays, figures


def disk_figures(arrays: dict[str, Any], frames: int) -> dict[str, Any]:
    """The stored size (``workers.store.npz_bytes``), per frame, and the largest arrays."""
    from workers.store import npz_bytes

    disk = len(npz_bytes(arrays))
    largest = sorted(((int(np.asarray(v).nbytes), k) for k, v in arrays.items()), reverse=True)[:6]
    return {
        "disk_mb": round(disk / 1e6, 1),
        "bytes_per_frame": round(disk / frames),
        "largest_arrays_mb": {k: round(b / 1e6, 1) for b, k in largest},
    }


def build_one(
    frames: int, candidates: str, with_recall: bool, keep: Path | None, eighth: bool
) -> dict[str, Any]:
    """Build the library of ``frames`` (or every 8th clip of it with ``eighth``) and measure it;
    with ``keep``, the arrays go to ``keep/graph-<frames>[-eighth].npz`` and the figures beside them."""
    from motion.allocator import tune_process

    tune_process()  # as every Segue process does
    load_avg = os.getloadavg()[0]
    library, made_of = library_of(frames)
    if eighth:
        library = subset(library, 8)
        made_of = f"every 8th clip of ({made_of})"
    rss_library = rss_mb()
    arrays, out = build_arrays(library, candidates)
    out["made_of"] = made_of
    if with_recall:
        out.update(recall(library, arrays))
    out.update(disk_figures(arrays, out["frames"]))
    out["peak_rss_build_mb"] = round(rss_mb(), 1)
    out["rss_library_mb"] = round(rss_library, 1)
    out["build_load_avg"] = round(load_avg, 2)
    if keep is not None:
        stem = keep / f"graph-{frames}{'-eighth' if eighth else ''}"
        np.savez(f"{stem}.npz", **arrays)
        Path(f"{stem}.json").write_text(json.dumps(out))
    return out


def subset(library: Any, k: int) -> Any:
    """Every ``k``-th clip of a library."""
    from engines.library import MotionLibrary

    pick = range(0, len(library.names), k)
    return MotionLibrary(
        tuple(library.names[i] for i in pick),
        tuple(library.motions[i] for i in pick),
        tuple(library.labels[i] for i in pick),
    )


def cpu_emitter() -> Any:
    from engines.base import CollectingEmitter, Solution

    class CpuEmitter(CollectingEmitter):
        """Also the process CPU time of every solution."""

        def __init__(self) -> None:
            super().__init__()
            self.cpu: list[float] = []

        def solution(self, solution: Solution) -> str:
            self.cpu.append(time.process_time())
            return super().solution(solution)

    return CpuEmitter()


def body_goal_request(
    frames: int, seed: int, budget: float, goal: tuple[float, float, float]
) -> dict[str, Any]:
    """A graph request of ``frames`` frames from the origin facing +Z to the body goal ``goal =
    (x, z, heading_deg)`` (metres, degrees) at its last frame (the benches' far and near goals)."""
    x, z, heading = goal
    return {
        "engine": "graph",
        "frames": frames,
        "seed": seed,
        "budget_s": budget,
        "constraints": [
            {"type": "body", "frame": 0, "position": [0.0, 0.0], "heading_deg": 0.0},
            {"type": "body", "frame": frames - 1, "position": [x, z], "heading_deg": heading},
        ],
    }


def search_one(path: Path, seeds: list[int], seconds: float, goal_m: float, budget: float) -> dict[str, Any]:
    """Load a kept database as an engine process does and answer the far-goal request once per
    seed (module docstring); the figures of the first seed, and every seed's verdict."""
    from threadpoolctl import threadpool_limits  # type: ignore[import-untyped]

    from engines.graph.engine import GraphEngine
    from engines.library import library_from_arrays
    from engines.registry import parse_job_request
    from motion.allocator import tune_process
    from motion.ground import body_root

    tune_process()
    out: dict[str, Any] = {"search_load_avg": round(os.getloadavg()[0], 2)}
    t0, c0 = time.perf_counter(), time.process_time()
    with np.load(path, allow_pickle=False) as z:
        loaded = {k: z[k] for k in z.files}
    engine = GraphEngine(library_from_arrays(loaded), loaded)
    out["load_s"] = round(time.perf_counter() - t0, 2)
    out["load_cpu_s"] = round(time.process_time() - c0, 2)
    out["rss_loaded_mb"] = round(rss_mb(), 1)
    n = round(seconds * 30)
    verdicts = []
    for seed in seeds:
        request = parse_job_request(body_goal_request(n, seed, budget, (goal_m, 0.0, 90.0)))
        searcher = engine.searcher(request.seed)
        rec = cpu_emitter()
        t0, c0 = time.perf_counter(), time.process_time()
        with threadpool_limits(limits=1, user_api="blas"):  # as GraphEngine.search does
            stopped = searcher.run(request, budget, rec, lambda: False)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        best = min(rec.solutions, key=lambda s: float(s.score))
        pos = best.motion.global_positions() * best.motion.metres_per_unit
        end = np.asarray(pos[-1, body_root(best.motion.skeleton), [0, 2]])
        error_cm = round(float(np.linalg.norm(end - [goal_m, 0.0])) * 100, 1)
        ok = None if best.quality is None else best.quality.ok
        verdicts.append(
            {
                "seed": seed,
                "goal_error_cm": error_cm,
                "ok": ok,
                "score": round(float(best.score), 3),
                "reasons": [] if best.quality is None else best.quality.reasons,
            }
        )
        if len(verdicts) == 1:
            first_cpu = round(rec.cpu[0] - c0, 3)
            out.update(
                {
                    "request_frames": n,
                    "first_solution_s": round(rec.times[0], 3),
                    "first_solution_cpu_s": first_cpu,
                    "rounds": searcher.rounds_,
                    "stopped": stopped.value,
                    "round_s": round((wall - rec.times[0]) / max(searcher.rounds_, 1), 3),
                    "round_cpu_s": round((cpu - first_cpu) / max(searcher.rounds_, 1), 3),
                    "search_s": round(wall, 2),
                    "search_cpu_s": round(cpu, 2),
                    "goal_error_cm": error_cm,
                    "ok": ok,
                    "reasons": [] if best.quality is None else best.quality.reasons,
                }
            )
    out["seeds"] = verdicts
    out["peak_rss_mb"] = round(rss_mb(), 1)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument(
        "--sizes", default="10000,40000,100000,200000,400000,1000000", help="frames, comma-separated"
    )
    ap.add_argument("--candidates", default="indexed", choices=("auto", "indexed", "all_pairs"))
    ap.add_argument("--recall", action="store_true", help="also the all-pairs build (sizes <= 40k)")
    ap.add_argument(
        "--eighth", action="store_true", help="also every 8th clip of each size: the CPU exponent"
    )
    ap.add_argument("--keep", type=Path, help="keep each built database here (and reuse it with --reuse)")
    ap.add_argument("--reuse", action="store_true", help="search the kept databases instead of building")
    ap.add_argument("--seeds", default="1", help="request seeds, comma-separated (the figures: the first)")
    ap.add_argument("--seconds", type=float, default=20.0, help="length of the requested motion (s)")
    ap.add_argument("--goal", type=float, default=12.0, help="distance of the body goal (m)")
    ap.add_argument("--budget", type=float, default=120.0, help="safety time cap of each search (s)")
    ap.add_argument("--one", type=int, help=argparse.SUPPRESS)  # one build in this process
    ap.add_argument("--one-eighth", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--search", type=Path, help=argparse.SUPPRESS)  # one search in this process
    args = ap.parse_args(argv)
    if not DATA.exists():
        print(json.dumps({"skipped": f"no data at {DATA}"}))
        return 0
    seeds = [int(s) for s in args.seeds.split(",")]
    if args.one:
        with_recall = args.recall and args.one <= 40000
        print(json.dumps(build_one(args.one, args.candidates, with_recall, args.keep, args.one_eighth)))
        return 0
    if args.search:
        print(json.dumps(search_one(args.search, seeds, args.seconds, args.goal, args.budget)))
        return 0
    tmp = None
    keep = args.keep
    if keep is None:
        tmp = tempfile.TemporaryDirectory()
        keep = Path(tmp.name)
    keep.mkdir(parents=True, exist_ok=True)

    def child(*extra: str) -> dict[str, Any]:
        cmd = [sys.executable, __file__, *extra]
        done = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
        return dict(json.loads(done.strip().splitlines()[-1]))

    try:
        for size in (int(s) for s in args.sizes.split(",")):
            stem = keep / f"graph-{size}"
            if args.reuse and Path(f"{stem}.json").exists():
                out = json.loads(Path(f"{stem}.json").read_text())
            else:
                flags = ["--candidates", args.candidates, "--keep", str(keep)]
                out = child("--one", str(size), *flags, *(["--recall"] if args.recall else []))
            if args.eighth:
                small_stem = keep / f"graph-{size}-eighth"
                if args.reuse and Path(f"{small_stem}.json").exists():
                    small = json.loads(Path(f"{small_stem}.json").read_text())
                else:
                    small = child(
                        "--one",
                        str(size),
                        "--one-eighth",
                        "--candidates",
                        args.candidates,
                        "--keep",
                        str(keep),
                    )
                ratio = out["frames"] / small["frames"]
                out["eighth"] = {
                    k: small[k] for k in ("frames", "build_cpu_s", "peak_rss_build_mb", "leaf_edges")
                }
                out["cpu_exponent"] = round(
                    float(np.log(out["build_cpu_s"] / small["build_cpu_s"]) / np.log(ratio)), 3
                )
            found = child(
                "--search",
                f"{stem}.npz",
                "--seeds",
                args.seeds,
                "--seconds",
                str(args.seconds),
                "--goal",
                str(args.goal),
                "--budget",
                str(args.budget),
            )
            out.update(found)
            print(json.dumps(out), flush=True)
    finally:
        if tmp is not None:
            tmp.cleanup()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
