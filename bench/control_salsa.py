"""Accuracy of the control-by-example engine: leave-one-dance-out on the CMU salsa couples.

Usage: ``python bench/control_salsa.py [--held 07,12] [--jobs 2] [--yaw 25] [--move 0.8,-1.1]
[--budget 10] [--cache DIR] [--request JSON] [--database JSON] [--baselines] [--bodies 0,-0.01]``
from the project root (needs ../shared/data/cmu-salsa; ``--database`` adds database spec fields).

The protocol of ``../shared/acceptance/control.py``, run in process: for each held-out dance ``NN``
of the 14 couples (``60_NN`` leader, ``61_NN`` follower), a ``control`` database is built from the
other 13 pairs (beats segmentation, 2 beats per segment); the held-out leader and follower are moved
rigidly on the floor (rotated about +Y by ``--yaw`` degrees, then translated by ``--move X,Z`` in the
BVH file's units, as the check's ``yaw_transform``); the follower is generated from the moved
leader (the engine's best solution within ``--budget`` seconds; default the requests' 10 s, as the
check's ``segue synth``; ``--request`` adds request fields such as ``k``), and compared with the
moved real follower, output frame ``i`` against the follower frame nearest in time.

``--bodies T1,T2,...`` tells every request where the real follower's body stands at those times
(seconds, negative from the end; request ``bodies``): the accuracy a user gets who says where the
follower starts and ends, which the leader's motion does not say.

``--settings`` compares several request settings (name -> request fields) on the same databases;
every figure is given per dance and per setting.

Prints one JSON object on stdout (progress lines go to stderr)::

    {"dances": {"07": {"build_s", "instances",
                       "<setting>": {"error_x_height", "placement_x_height", "pose_x_height",
                                     "jerk_m_s3", "foot_slide_m_s", "handhold_held", "synth_s",
                                     "frames"}, ...}, ...},
     "settings": {"<setting>": {"mean_error_x_height", "worst_error_x_height", "dances_over_0_17",
                                "mean_jerk_m_s3", "mean_foot_slide_m_s", "median_synth_s",
                                "reports_ok"}},
     "load_avg"}

* ``error_x_height``: the check's figure — mean distance between the generated and the real
  follower's hip, head, rHand, lHand, rFoot and lFoot (all frames, all six points), divided by the
  leader's standing height (its maximum head height above the floor);
* ``placement_x_height``: where the follower stands — mean horizontal (X, Z) distance between the
  generated and the real hip, same unit;
* ``pose_x_height``: the pose with the placement taken out — mean distance between the other five
  points expressed relative to the hip (world axes, so the heading still counts), same unit;
* ``jerk_m_s3``: mean |third derivative| of the six points of the output (m/s³);
* ``foot_slide_m_s``: the output's mean horizontal foot speed while the contacts the engine carried
  over from the examples say the foot is planted (m/s, :func:`motion.metrics.foot_slip`);
* ``handhold_held``: of the output frames whose examples hold hands, the fraction where a hand of
  the output is within the database's ``handhold_m`` of a hand of the leader (the quality report's
  ``handhold`` entry);
* ``build_s``: seconds to build the database (library + control arrays), ``null`` when it was loaded
  from ``--cache``; ``synth_s``: seconds of the whole search request; ``frames``: output frames;
  ``instances``: instances the database keeps after clustering;
* ``dances_over_0_17``: the dances whose error exceeds 0.17 (the earlier acceptance bar);
* ``load_avg``: the machine's 1, 5 and 15 minute load averages at the end (timings are noisy on a
  shared machine).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import sys
import time
from dataclasses import replace
from multiprocessing import Pool
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from engines.base import CollectingEmitter, Run  # noqa: E402
from engines.control.engine import ControlEngine  # noqa: E402
from engines.library import (  # noqa: E402
    ClipInput,
    build_library,
    library_from_arrays,
    library_to_arrays,
)
from engines.registry import parse_database_spec, parse_job_request  # noqa: E402
from motion import Motion  # noqa: E402
from motion import rotations as rot  # noqa: E402
from motion.allocator import tune_process  # noqa: E402
from motion.bvh import bvh_text, parse_bvh  # noqa: E402
from motion.ground import from_ground_frame, ground_frames, to_ground_frame  # noqa: E402
from motion.metrics import foot_slip, points_jerk  # noqa: E402
from workers.store import load_npz, npz_bytes  # noqa: E402

SALSA = ROOT.parent / "shared" / "data" / "cmu-salsa"
POINTS = ("hip", "head", "rHand", "lHand", "rFoot", "lFoot")
BAR = 0.17
# sources whose change invalidates a cached database (the key also holds the spec itself)
CACHE_SOURCES = (
    *sorted((ROOT / "engines" / "control").glob("*.py")),
    ROOT / "engines" / "library.py",
    *sorted((ROOT / "motion").glob("*.py")),
)


def log(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


def trials() -> list[str]:
    """The salsa trial numbers (``"01"`` ...) that have a leader file."""
    return sorted({f.name[3:5] for f in SALSA.glob("60_*_scaled.bvh")})


def database_spec(held: str, extra: dict[str, Any] | None = None) -> dict[str, Any]:
    """The check's database: every couple but ``held``, beats segmentation (2 beats per segment),
    with ``extra`` spec fields (e.g. ``cluster_threshold_m``) on top."""
    return {
        "kind": "control",
        "pairs": [
            {"control": str(SALSA / f"60_{t}_scaled.bvh"), "target": str(SALSA / f"61_{t}_scaled.bvh")}
            for t in trials()
            if t != held
        ],
        "segmentation": {"method": "beats", "beats_per_segment": 2},
        **(extra or {}),
    }


def cache_key(spec_data: dict[str, Any]) -> str:
    """A digest of the spec, the input files' sizes and times, and the engine and motion sources."""
    h = hashlib.sha256(json.dumps(spec_data, sort_keys=True).encode())
    for pair in spec_data["pairs"]:
        for path in pair.values():
            st = Path(path).stat()
            h.update(f"{path}:{st.st_size}:{st.st_mtime_ns}".encode())
    for source in CACHE_SOURCES:
        h.update(source.read_bytes())
    return h.hexdigest()[:16]


def engine_for(
    held: str, cache: Path | None, extra: dict[str, Any] | None = None
) -> tuple[ControlEngine, float | None]:
    """The engine on the database without ``held`` and the seconds its build took (``None`` when
    it was loaded from ``cache``, where it is saved as ``db_<held>_<key>.npz`` after a build)."""
    spec_data = database_spec(held, extra)
    path = None if cache is None else cache / f"db_{held}_{cache_key(spec_data)}.npz"
    if path is not None and path.exists():
        arrays = load_npz(path.read_bytes())
        return ControlEngine(library_from_arrays(arrays), arrays), None
    t0 = time.perf_counter()
    spec = parse_database_spec(spec_data)
    clips = [ClipInput(c.display_name(), Path(str(c.bvh)).read_bytes(), c.units) for c in spec.clips]
    library = build_library(clips, spec.fps)
    arrays = ControlEngine.build(spec, library, CollectingEmitter(), lambda: False)
    arrays.update(library_to_arrays(library))
    build_s = time.perf_counter() - t0
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f"{path.stem}.{os.getpid()}.tmp")
        tmp.write_bytes(npz_bytes(arrays))
        tmp.replace(path)
    return ControlEngine(library, arrays), build_s


def moved(motion: Motion, yaw_deg: float, tx: float, tz: float) -> Motion:
    """``motion`` rotated about +Y (through the world origin) by ``yaw_deg`` degrees, then translated
    by ``(tx, 0, tz)`` in the motion's own units — the check's ``yaw_transform`` on the root channels."""
    turn = rot.from_yaw(np.radians(yaw_deg))
    root = rot.rotate(turn, motion.root_positions) + np.array([tx, 0.0, tz])
    rotations = motion.rotations.copy()
    rotations[:, 0] = rot.multiply(turn, rotations[:, 0])
    return replace(motion, root_positions=root, rotations=rotations)


def follower_errors(out: Motion, follower: Motion, leader: Motion) -> dict[str, float]:
    """Errors of ``out`` against ``follower`` (frame ``i`` of ``out`` vs the follower's nearest frame
    in time) over :data:`POINTS`, divided by the leader's maximum head height (all in metres)."""
    op = out.global_positions() * out.metres_per_unit  # (F, J, 3) metres
    gp = follower.global_positions() * follower.metres_per_unit
    lp = leader.global_positions() * leader.metres_per_unit
    height = float(lp[:, leader.skeleton.names.index("head"), 1].max())
    gi = np.clip(
        np.round(np.arange(out.num_frames) * follower.fps / out.fps).astype(int), 0, follower.num_frames - 1
    )
    o = op[:, [out.skeleton.names.index(n) for n in POINTS]]  # (F, 6, 3), hip first
    g = gp[gi][:, [follower.skeleton.names.index(n) for n in POINTS]]
    error = np.linalg.norm(o - g, axis=-1).mean() / height
    placement = np.linalg.norm((o[:, 0] - g[:, 0])[:, [0, 2]], axis=-1).mean() / height
    pose = np.linalg.norm((o - o[:, :1]) - (g - g[:, :1]), axis=-1)[:, 1:].mean() / height
    return {
        "error_x_height": round(float(error), 4),
        "placement_x_height": round(float(placement), 4),
        "pose_x_height": round(float(pose), 4),
    }


LEADER_POINTS = ("hip", "head", "rHand", "lHand")  # the engine's default control cloud


def _points(motion: Motion, names: tuple[str, ...]) -> np.ndarray:
    """``(F, len(names), 3)`` metres: the named joints' world positions."""
    pos = motion.global_positions() * motion.metres_per_unit
    return np.asarray(pos[:, [motion.skeleton.names.index(n) for n in names]])


def _leader_frames(motion: Motion) -> tuple[np.ndarray, np.ndarray]:
    """The leader's floor origin ``(F, 2)`` metres and heading ``(F,)`` radians."""
    origin, head = ground_frames(motion)
    return origin * motion.metres_per_unit, head


def _window_features(motion: Motion, half_s: float, samples: int) -> np.ndarray:
    """``(F, samples * 4 * 3)``: the leader's hip, head and hands at ``samples`` instants spanning
    ``+-half_s`` around each frame (clamped at the ends), in that frame's ground frame (metres)."""
    pts = _points(motion, LEADER_POINTS)
    origin, head = _leader_frames(motion)
    n = motion.num_frames
    offs = np.round(np.linspace(-half_s, half_s, samples) * motion.fps).astype(int)
    idx = np.clip(np.arange(n)[:, None] + offs[None, :], 0, n - 1)  # (F, samples)
    local = to_ground_frame(pts[idx].reshape(n, -1, 3), origin, head)
    return np.asarray(local.reshape(n, -1))


def nearest_frame_follower(
    pairs: list[tuple[Motion, Motion]],
    leader: Motion,
    half_s: float = 0.25,
    samples: int = 5,
    step_s: float = 0.1,
) -> np.ndarray:
    """The nearest-frame baseline (motion matching): every ``step_s`` seconds, the database frame
    whose leader window (:func:`_window_features`) is nearest in Euclidean distance to the input
    leader's; between searches the matched follower plays on frame by frame (within its clip). The
    follower's :data:`POINTS` are taken relative to the database leader of their frame and placed
    relative to the input leader of the output frame. Returns ``(F, 6, 3)`` metres."""
    feats, rel, last = [], [], []
    offset = 0
    for lead, follow in pairs:
        n = min(lead.num_frames, follow.num_frames)
        lead, follow = lead.slice(0, n), follow.slice(0, n)
        feats.append(_window_features(lead, half_s, samples))
        origin, head = _leader_frames(lead)
        rel.append(to_ground_frame(_points(follow, POINTS), origin, head))
        last.append(np.full(n, offset + n - 1))
        offset += n
    db = np.concatenate(feats)
    db_rel = np.concatenate(rel)
    db_last = np.concatenate(last)
    db_sq = (db**2).sum(1)
    q = _window_features(leader, half_s, samples)
    n_out = q.shape[0]
    step = max(1, int(round(step_s * leader.fps)))
    searched = np.arange(0, n_out, step)
    match = np.empty(searched.size, dtype=np.intp)
    for a in range(0, searched.size, 256):  # chunks of queries: never a frames x frames matrix
        d = db_sq[None, :] - 2.0 * q[searched[a : a + 256]] @ db.T
        match[a : a + 256] = np.argmin(d, axis=1)
    k = np.arange(n_out) // step
    frame = np.minimum(match[k] + np.arange(n_out) - searched[k], db_last[match[k]])
    origin, head = _leader_frames(leader)
    return np.asarray(from_ground_frame(db_rel[frame], origin, head))


def average_partner(pairs: list[tuple[Motion, Motion]], leader: Motion) -> np.ndarray:
    """The average-partner baseline: the follower's :data:`POINTS` averaged over every database frame
    in its leader's ground frame, placed relative to the input leader. ``(F, 6, 3)`` metres."""
    rel = []
    for lead, follow in pairs:
        n = min(lead.num_frames, follow.num_frames)
        origin, head = _leader_frames(lead.slice(0, n))
        rel.append(to_ground_frame(_points(follow.slice(0, n), POINTS), origin, head))
    mean = np.concatenate(rel).mean(axis=0)
    origin, head = _leader_frames(leader)
    return np.asarray(from_ground_frame(np.repeat(mean[None], leader.num_frames, 0), origin, head))


def points_error(points: np.ndarray, follower: Motion, height: float) -> float:
    """Mean distance of ``points (F, 6, 3)`` (at the follower's rate) to the follower's, / height."""
    n = min(points.shape[0], follower.num_frames)
    return float(np.linalg.norm(points[:n] - _points(follower, POINTS)[:n], axis=-1).mean() / height)


def baselines(held: str, leader: Motion, follower: Motion, out: Motion) -> dict[str, Any]:
    """Error (x height) and jerk of the two baselines of the issue, and the jerk of the engine's
    output and of the real follower, all on the six :data:`POINTS` at the control's rate."""
    pairs = [
        (
            parse_bvh((SALSA / f"60_{t}_scaled.bvh").read_bytes()),
            parse_bvh((SALSA / f"61_{t}_scaled.bvh").read_bytes()),
        )
        for t in trials()
        if t != held
    ]
    height = float(_points(leader, ("head",))[:, 0, 1].max())
    nearest = nearest_frame_follower(pairs, leader)
    average = average_partner(pairs, leader)
    return {
        "nearest_frame_x_height": round(points_error(nearest, follower, height), 4),
        "average_partner_x_height": round(points_error(average, follower, height), 4),
        "jerk_compared_m_s3": {
            "output": round(points_jerk(_points(out, POINTS), out.fps), 1),
            "nearest_frame": round(points_jerk(nearest, leader.fps), 1),
            "real_follower": round(points_jerk(_points(follower, POINTS), follower.fps), 1),
        },
    }


def synthesize(
    engine: ControlEngine, leader: Motion, extra: dict[str, Any], budget: float | None
) -> tuple[Any, float]:
    """The engine's best solution for ``leader`` with request fields ``extra``, and the seconds the
    whole request took (parse, interpret, solve, re-time, assemble)."""
    request_data: dict[str, Any] = {**extra, "engine": "control", "control": {"bvh": "lead.bvh"}}
    if budget is not None:
        request_data["budget_s"] = budget
    request = parse_job_request(request_data)
    request.attach_inputs({"lead.bvh": bvh_text(leader).encode()})
    quiet = CollectingEmitter()
    t0 = time.perf_counter()
    engine.search(request, Run(request.budget_s, emit=quiet))
    synth_s = time.perf_counter() - t0
    if not quiet.solutions:
        raise RuntimeError(f"the engine found no solution within {request.budget_s} s")
    return min(quiet.solutions, key=lambda s: s.score), synth_s  # the runtime's best result


def output_measures(solution: Any) -> dict[str, Any]:
    """Jerk of the six points (m/s^3), foot slide while the propagated contacts are planted (m/s)
    and the fraction of the propagated hand-hold frames whose hands meet (quality report)."""
    out = solution.motion
    fc = solution.annotations["foot_contacts"]
    joints = np.array([out.skeleton.names.index(n) for n in fc["joints"]], dtype=np.intp)
    flags = np.asarray(fc["flags"], dtype=bool).T
    hold = solution.quality.constraint_errors.get("handhold") if solution.quality is not None else None
    return {
        "jerk_m_s3": round(points_jerk(_points(out, POINTS), out.fps), 1),
        "foot_slide_m_s": round(foot_slip(out, contacts=flags, joints=joints), 4),
        "handhold_held": None if hold is None else hold.get("held_fraction"),
        "ok": None if solution.quality is None else bool(solution.quality.ok),
        "reasons": [] if solution.quality is None else list(solution.quality.reasons),
    }


def run_dance(
    job: tuple[
        str,
        float,
        float,
        float,
        float | None,
        str | None,
        dict[str, dict[str, Any]],
        bool,
        dict[str, Any],
        list[float],
    ],
) -> tuple[str, dict[str, Any]]:
    """One held-out dance: build (or load), move, then for every setting synthesize and measure
    (and the baselines, on the first setting's output)."""
    held, yaw, tx, tz, budget, cache, settings, with_baselines, db_extra, body_times = job
    engine, build_s = engine_for(held, None if cache is None else Path(cache), db_extra)
    leader = moved(parse_bvh((SALSA / f"60_{held}_scaled.bvh").read_bytes()), yaw, tx, tz)
    follower = moved(parse_bvh((SALSA / f"61_{held}_scaled.bvh").read_bytes()), yaw, tx, tz)
    result: dict[str, Any] = {
        "build_s": None if build_s is None else round(build_s, 1),
        "instances": int(engine.kept_.size),
    }
    bodies = follower_bodies(follower, body_times)
    for k, (name, extra) in enumerate(settings.items()):
        solution, synth_s = synthesize(engine, leader, {**extra, **bodies}, budget)
        out = solution.motion
        ratio = (out.num_frames / out.fps) / (follower.num_frames / follower.fps)  # as the check
        if abs(ratio - 1.0) > 0.02:
            log(f"warning: dance {held}: output lasts {ratio:.3f}x the control motion (the check fails > 2%)")
        entry = {
            **follower_errors(out, follower, leader),
            **output_measures(solution),
            "synth_s": round(synth_s, 2),
            "frames": out.num_frames,
        }
        if with_baselines and k == 0:
            entry.update(baselines(held, leader, follower, out))
        log(f"dance {held} [{name}]: {json.dumps(entry)}")
        result[name] = entry
    return held, result


def follower_bodies(follower: Motion, times: list[float]) -> dict[str, Any]:
    """Request fields placing the target's body where the real (moved) follower's hips are at
    ``times`` (seconds; negative ones count from the end): what a user who knows where the follower
    stands would give (``{}`` for no times)."""
    if not times:
        return {}
    hips = _points(follower, ("hip",))[:, 0]
    duration = (follower.num_frames - 1) / follower.fps
    bodies = []
    for t in times:
        at = min(max(duration + t if t < 0 else t, 0.0), duration)
        frame = min(int(round(at * follower.fps)), follower.num_frames - 1)
        bodies.append({"time_s": round(at, 4), "position": [float(hips[frame, 0]), float(hips[frame, 2])]})
    return {"bodies": bodies}


def held_dances(ap: argparse.ArgumentParser, text: str | None) -> list[str]:
    """The dances a ``--held`` option names (``"07,10"``; ``None``: all of them); a usage error
    naming any that is not in the data."""
    available = trials()
    held = available if text is None else [h.strip().zfill(2) for h in text.split(",") if h.strip()]
    unknown = [h for h in held if h not in available]
    if unknown or not held:
        named = ", ".join(unknown) or "(none given)"
        ap.error(f"--held: unknown dance(s) {named}; have {','.join(available)}")
    return held


def json_object(ap: argparse.ArgumentParser, option: str, text: str) -> dict[str, Any]:
    """The JSON object given to ``option``; a usage error naming the option otherwise."""
    try:
        value = json.loads(text)
    except json.JSONDecodeError as exc:
        ap.error(f"{option} is not JSON: {exc}")
    if not isinstance(value, dict):
        ap.error(f"{option} takes a JSON object")
    return value


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--held", default=None, help="held-out dances, comma separated (default: all 14)")
    ap.add_argument("--jobs", type=int, default=1, help="dances run in parallel processes")
    ap.add_argument("--yaw", type=float, default=25.0, help="rotation of the held-out couple, degrees")
    ap.add_argument("--move", default="0.8,-1.1", help="floor translation X,Z of the held-out couple")
    ap.add_argument("--budget", type=float, default=None, help="search budget, s (default: the request's)")
    ap.add_argument(
        "--request", default="{}", help="extra request fields as a JSON object, e.g. '{\"k\": 0.2}'"
    )
    ap.add_argument(
        "--settings",
        default=None,
        help="settings to compare, a JSON object of name -> request fields, e.g. "
        '\'{"k 0.1": {}, "k 0.2": {"k": 0.2}}\' (default: one setting, \'default\', with --request)',
    )
    ap.add_argument(
        "--database",
        default="{}",
        help="extra database spec fields as a JSON object, e.g. '{\"cluster_threshold_m\": 0.05}'",
    )
    ap.add_argument(
        "--baselines",
        action="store_true",
        help="also measure the nearest-frame and average-partner baselines and the jerk of each",
    )
    ap.add_argument("--cache", type=Path, default=None, help="directory to keep built databases in")
    ap.add_argument(
        "--bodies",
        default="",
        help="comma-separated times (s; negative from the end) at which every request is told where the "
        "real follower's body stands (request 'bodies'), e.g. '0,-0.01' for the start and end spots",
    )
    args = ap.parse_args(argv)
    tune_process()
    if not SALSA.exists():
        print(json.dumps({"error": f"{SALSA} not found"}))
        return 1
    held = held_dances(ap, args.held)
    try:
        tx, tz = (float(v) for v in args.move.split(","))
    except ValueError:
        ap.error(f"--move takes X,Z (two numbers), got {args.move!r}")
    if args.jobs < 1:
        ap.error("--jobs must be at least 1")
    if args.budget is not None and args.budget <= 0:
        ap.error("--budget must be positive")
    extra = json_object(ap, "--request", args.request)
    settings = {"default": extra} if args.settings is None else json_object(ap, "--settings", args.settings)
    if not settings or not all(isinstance(v, dict) for v in settings.values()):
        ap.error("--settings takes a JSON object of name -> request fields (objects)")
    db_extra = json_object(ap, "--database", args.database)
    cache = None if args.cache is None else str(args.cache.resolve())
    try:
        body_times = [float(v) for v in args.bodies.split(",") if v.strip()]
    except ValueError:
        ap.error(f"--bodies takes comma-separated seconds, got {args.bodies!r}")
    common = (args.budget, cache, settings, args.baselines, db_extra, body_times)
    jobs = [(h, args.yaw, tx, tz, *common) for h in held]
    log(f"{len(jobs)} held-out dance(s): {','.join(held)}; {args.jobs} process(es)")
    if args.jobs == 1:
        results = [run_dance(job) for job in jobs]
    else:
        with Pool(min(args.jobs, len(jobs)), initializer=tune_process) as pool:
            results = pool.map(run_dance, jobs, chunksize=1)
    dances = dict(sorted(results))
    summary = {}
    for name in settings:
        per = {h: d[name] for h, d in dances.items()}
        errors = [e["error_x_height"] for e in per.values()]
        summary[name] = {
            "mean_error_x_height": round(float(np.mean(errors)), 4),
            "worst_error_x_height": round(float(np.max(errors)), 4),
            "dances_over_0_17": [h for h, e in per.items() if e["error_x_height"] > BAR],
            "mean_jerk_m_s3": round(float(np.mean([e["jerk_m_s3"] for e in per.values()])), 1),
            "mean_foot_slide_m_s": round(float(np.mean([e["foot_slide_m_s"] for e in per.values()])), 4),
            "median_synth_s": round(float(np.median([e["synth_s"] for e in per.values()])), 2),
            "reports_ok": sum(1 for e in per.values() if e["ok"]),
        }
    load = [round(x, 2) for x in os.getloadavg()]
    print(json.dumps({"dances": dances, "settings": summary, "load_avg": load}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
