"""Benchmark: does synthesis obey an edited movement graph? (KPS03 Sec. 4.3; engines.rhythm.choreography)

Builds a rhythm database of salsa leaders (cmu-salsa from ../shared/data, ``--clips``; else the
bundled samples), with an ``--edge-threshold`` that leaves the learned graph sparse. Then, for each
of ``--trials`` trials, draws a random edit list on it (``--cuts`` cuts, ``--connects`` added
transitions, one weight by a factor in [2, 8]; lists the rules refuse are drawn again and counted),
derives the database, dances ``--seeds`` dances of ``--seconds`` s at ``--bpm`` on it (default 80,
slower than these dancers' 87 BPM: a tempo that allows every movement; one dancer,
free: the engine's own synthesis, whose group sequence the report's ``annotations.movements``
holds) and checks every edit on the group sequences:

* **cut**: the transition is never taken;
* **graph**: every transition taken is in the edited graph;
* **connect**: the added transition is taken at least once, when its source group was visited
  often enough that the edited probability gives it 5 expected takes ("when the music allows");
* **weight**: the weighted transition's share of its source's departures is within 3 binomial
  standard deviations of its edited probability (when the source was visited 30 times or more).

A trial obeys every edit when all its checkable edits pass. Prints one JSON object with the counts,
the mean total-variation distance between the observed and the edited transition rows (the
probabilities synthesis draws with on the edited graph: the graph times the beat-clarity
preference, :func:`engines.rhythm.synth.draw_probabilities`, what ``segue graph`` shows), and the
time to derive a database (``derive_ms``: resolve, apply, check and write the npz).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from engines.library import ClipInput  # noqa: E402
from engines.registry import parse_database_spec  # noqa: E402
from engines.rhythm.choreography import GraphEditError, apply_edits, edited_arrays  # noqa: E402
from engines.rhythm.engine import RhythmEngine, music_beats  # noqa: E402
from engines.rhythm.synth import draw_probabilities  # noqa: E402
from schemas.movement_graph import ResolvedEdit  # noqa: E402
from schemas.rhythm import RhythmRequest  # noqa: E402
from workers.execute import build_database_bytes  # noqa: E402
from workers.store import load_npz, npz_bytes  # noqa: E402

DATA = ROOT.parent / "shared" / "data" / "cmu-salsa"


def build(clips: list[str], threshold: float) -> tuple[dict[str, Any], str]:
    files = [DATA / f"60_{c}_scaled.bvh" for c in clips]
    if all(f.exists() for f in files):
        inputs = [ClipInput(f.stem, f.read_bytes()) for f in files]
        label = "cmu-salsa leaders " + ",".join(clips)
    else:
        from motion.samples import sample_path
        from tests.engines.rhythm_salsa import SAMPLES

        inputs = [ClipInput(n, sample_path(n).read_bytes()) for n in SAMPLES]
        label = "bundled salsa leader samples"
    spec = {
        "kind": "rhythm",
        "clips": [{"bvh": c.name} for c in inputs],
        "fps": 30,
        "beats_per_movement": 4,
        "edge_threshold": threshold,
    }
    data, _ = build_database_bytes(parse_database_spec(spec), inputs, lambda *_: None, lambda: False)
    return load_npz(data), label


def random_edits(
    p: np.ndarray, rng: np.random.Generator, cuts: int, connects: int
) -> tuple[list[ResolvedEdit], int]:
    """A random edit list the rules accept, and how many lists they refused before it."""
    k = p.shape[0]
    have = np.argwhere(p > 0)
    miss = np.argwhere(p == 0)
    refused = 0
    while True:
        cut = have[rng.choice(len(have), cuts, replace=False)]
        add = miss[rng.choice(len(miss), min(connects, len(miss)), replace=False)]
        cut_set = {(int(a), int(b)) for a, b in cut}
        keep = [(int(a), int(b)) for a, b in have if (int(a), int(b)) not in cut_set]
        wa, wb = keep[int(rng.integers(len(keep)))]
        edits = [ResolvedEdit(op="cut", source=int(a), target=int(b)) for a, b in cut]
        edits += [ResolvedEdit(op="connect", source=int(a), target=int(b)) for a, b in add]
        edits.append(
            ResolvedEdit(op="weight", source=wa, target=wb, weight=round(float(rng.uniform(2, 8)), 3))
        )
        try:
            apply_edits(p, edits)
        except GraphEditError:
            refused += 1
            continue
        assert k == p.shape[1]
        return edits, refused


def walks(engine: RhythmEngine, seeds: range, bpm: float, seconds: float) -> list[list[int]]:
    out = []
    for seed in seeds:
        req = RhythmRequest.model_validate(
            {"engine": "rhythm", "music": {"bpm": bpm, "duration_s": seconds}, "seed": seed}
        )
        _, _, r = engine.synthesize(req, music_beats(req))
        out.append([int(m["group"]) for m in r.plans])
    return out


def check(edits: list[ResolvedEdit], p_edit: np.ndarray, ws: list[list[int]]) -> dict[str, Any]:
    k = p_edit.shape[0]
    counts = np.zeros((k, k), dtype=np.int64)
    for w in ws:
        np.add.at(counts, (np.asarray(w[:-1]), np.asarray(w[1:])), 1)
    visits = counts.sum(axis=1)
    res: dict[str, Any] = {"cut_ok": 0, "cut": 0, "connect_ok": 0, "connect": 0, "connect_untestable": 0}
    res |= {"weight_ok": 0, "weight": 0, "weight_untestable": 0}
    for e in edits:
        a, b = e.source, e.target
        if e.op == "cut":
            res["cut"] += 1
            res["cut_ok"] += int(counts[a, b] == 0)
        elif e.op == "connect":
            if p_edit[a, b] * visits[a] < 5:
                res["connect_untestable"] += 1
                continue
            res["connect"] += 1
            res["connect_ok"] += int(counts[a, b] > 0)
        else:
            if visits[a] < 30:
                res["weight_untestable"] += 1
                continue
            res["weight"] += 1
            q = p_edit[a, b]
            share = counts[a, b] / visits[a]
            res["weight_ok"] += int(abs(share - q) <= 3 * np.sqrt(q * (1 - q) / visits[a]) + 1e-12)
    res["foreign"] = int(counts[p_edit == 0].sum())
    seen = visits > 0
    obs = counts[seen] / visits[seen, None]
    res["tv"] = float(0.5 * np.abs(obs - p_edit[seen]).sum(axis=1).mean())
    res["obeyed"] = (
        res["cut_ok"] == res["cut"]
        and res["connect_ok"] == res["connect"]
        and res["weight_ok"] == res["weight"]
        and res["foreign"] == 0
    )
    return res


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--clips", default="02,04,06,10,11,12")
    ap.add_argument("--edge-threshold", type=float, default=0.08)
    ap.add_argument("--trials", type=int, default=20)
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--bpm", type=float, default=80.0)
    ap.add_argument("--cuts", type=int, default=3)
    ap.add_argument("--connects", type=int, default=2)
    args = ap.parse_args()
    t0 = time.perf_counter()
    arrays, label = build(args.clips.split(","), args.edge_threshold)
    build_s = time.perf_counter() - t0
    p = np.asarray(arrays["rhythm.p"])
    rng = np.random.default_rng(0)
    results = []
    derive_ms = []
    refused = 0
    for trial in range(args.trials):
        edits, r = random_edits(p, rng, args.cuts, args.connects)
        refused += r
        t = time.perf_counter()
        derived = edited_arrays(arrays, edits)
        npz = npz_bytes(derived)
        derive_ms.append((time.perf_counter() - t) * 1000)
        engine = RhythmEngine.load(load_npz(npz))
        assert isinstance(engine, RhythmEngine)
        ws = walks(engine, range(trial * 1000, trial * 1000 + args.seeds), args.bpm, args.seconds)
        draw = draw_probabilities(
            np.asarray(derived["rhythm.p"]),
            np.asarray(derived["rhythm.clarity"]),
            np.asarray(derived["rhythm.labels"]),
        )
        results.append(check(edits, draw, ws))
    total = {k: int(sum(r[k] for r in results)) for k in results[0] if k not in ("tv", "obeyed")}
    out = {
        "database": label,
        "groups": int(p.shape[0]),
        "learned_transitions": int((p > 0).sum()),
        "build_s": round(build_s, 2),
        "trials": args.trials,
        "obeyed_every_edit": int(sum(r["obeyed"] for r in results)),
        "edit_lists_refused_by_the_rules": refused,
        "dances_per_trial": args.seeds,
        "movements_per_dance": int(np.floor(args.seconds * args.bpm / 60 / 4)),
        **total,
        "tv_distance_mean": round(float(np.mean([r["tv"] for r in results])), 4),
        "derive_ms_median": round(float(np.median(derive_ms)), 1),
        "npz_mb": round(len(npz_bytes(arrays)) / 1e6, 2),
        "note": "2 shared cores, other jobs running",
    }
    print(json.dumps(out))


if __name__ == "__main__":
    main()
