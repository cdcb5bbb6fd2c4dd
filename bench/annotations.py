"""Benchmark of the annotation engine on the shared Bandai-Namco data; prints one JSON object.

    python bench/annotations.py [--part all|build|search|propagation] [--datasets 1,2]

* ``build``: build time of an annotated database of the whole set (dataset-1 and dataset-2; labels
  from the file names, ``--labelled`` clips per label labelled, the rest propagated), split into
  parsing and the engine's build; per-frame F1 of the propagated labels on the unlabelled clips.
* ``search``: on that database, the time of one 32/16/8 pass for a 30 s output (median of
  ``--repeats``), and passes / solutions per second in anytime mode (``--budget`` seconds).
* ``propagation``: on dataset-2, per-label and macro per-frame F1 on held-out clips as the number
  of labelled clips per label grows from 1 to 5 (the others held out; clips picked at random,
  ``--trials`` draws).

Figures are wall-clock on whatever else the machine runs; repeat for stable numbers.
"""

from __future__ import annotations

import argparse
import glob
import json
import re
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from engines.annotations.build import SVM_DIMS, build_annotated, embed_library, standardize  # noqa: E402
from engines.annotations.engine import AnnotationEngine, AnnotationSearch  # noqa: E402
from engines.annotations.propagate import propagate  # noqa: E402
from engines.base import CollectingEmitter  # noqa: E402
from engines.library import ClipInput, MotionLibrary, build_library, library_to_arrays  # noqa: E402
from schemas.annotations import AnnotatedDatabaseSpec, AnnotationRequest  # noqa: E402

DATA = ROOT.parent / "shared" / "data" / "bandai-namco"
NAME = re.compile(r"dataset-\d_(?P<label>[a-z-]+?)_(?P<style>[a-z-]+)_\d+\.bvh$")


def files(datasets: list[str]) -> list[tuple[str, str]]:
    out = []
    for d in datasets:
        for f in sorted(glob.glob(str(DATA / f"dataset-{d}" / "*.bvh"))):
            m = NAME.search(f)
            if m:
                out.append((f, m.group("label")))
    return out


def load(items: list[tuple[str, str]], labelled: set[int]) -> tuple[MotionLibrary, list[str]]:
    raw = [(Path(f).stem, Path(f).read_bytes()) for f, _ in items]
    lib = build_library([ClipInput(n, b) for n, b in raw], 30.0)
    clips = [
        ClipInput(
            n, b, None, [{"label": lab, "start": 0, "end": m.num_frames, "value": 1}] if i in labelled else []
        )
        for i, ((n, b), (_, lab), m) in enumerate(zip(raw, items, lib.motions, strict=True))
    ]
    return build_library(clips, 30.0), [lab for _, lab in items]


def pick_labelled(truth: list[str], per_label: int, rng: np.random.Generator) -> set[int]:
    out: set[int] = set()
    for lab in sorted(set(truth)):
        idx = [i for i, t in enumerate(truth) if t == lab]
        out.update(int(i) for i in rng.permutation(idx)[:per_label])
    return out


def f1_table(
    vocab: list[str], labels: np.ndarray, truth_of_frame: np.ndarray, held: np.ndarray
) -> dict[str, float]:
    out = {}
    for j, lab in enumerate(vocab):
        y = truth_of_frame[held] == lab
        p = labels[held, j] > 0
        tp = float(np.sum(y & p))
        denom = float(y.sum() + p.sum())
        if y.sum() == 0:
            continue
        out[lab] = round(2 * tp / denom, 4) if denom else 0.0
    return out


def clip_accuracy(
    vocab: list[str], labels: np.ndarray, counts: list[int], truth: list[str], held: set[int]
) -> float:
    """Fraction of held-out clips whose most frequent propagated label is their true label."""
    starts = np.concatenate(([0], np.cumsum(counts)[:-1]))
    hits = [
        vocab[int(np.argmax((labels[starts[i] : starts[i] + counts[i]] > 0).mean(axis=0)))] == truth[i]
        for i in sorted(held)
    ]
    return round(float(np.mean(hits)), 4) if hits else 0.0


def bench_build(args: argparse.Namespace) -> tuple[dict[str, Any], AnnotationEngine]:
    items = files(args.datasets.split(","))
    truth = [lab for _, lab in items]
    labelled = pick_labelled(truth, args.labelled, np.random.default_rng(0))
    t0 = time.perf_counter()
    lib, _ = load(items, labelled)
    t_parse = time.perf_counter() - t0
    spec = AnnotatedDatabaseSpec(clips=[{"bvh": Path(f).name} for f, _ in items])
    rec = CollectingEmitter()
    t0 = time.perf_counter()
    arrays = build_annotated(spec, lib, rec, lambda: False)
    t_build = time.perf_counter() - t0
    arrays.update(library_to_arrays(lib))
    engine = AnnotationEngine(lib, arrays)
    counts = [m.num_frames for m in lib.motions]
    truth_f = np.repeat(np.array(truth), counts)
    held = np.repeat(np.array([i not in labelled for i in range(len(items))]), counts)
    f1 = f1_table(engine.db.vocab, engine.db.labels, truth_f, held)
    report = json.loads(str(arrays["ann.report"]))
    return (
        {
            "clips": len(items),
            "frames": int(sum(counts)),
            "labels": len(engine.db.vocab),
            "labelled_clips_per_label": args.labelled,
            "parse_s": round(t_parse, 2),
            "engine_build_s": round(t_build, 2),
            "heldout_f1": f1,
            "heldout_f1_macro": round(float(np.mean(list(f1.values()))), 4),
            "heldout_clip_accuracy": clip_accuracy(
                engine.db.vocab,
                engine.db.labels,
                counts,
                truth,
                {i for i in range(len(items)) if i not in labelled},
            ),
            "cv": {r["label"]: r["cv"] for r in report},
        },
        engine,
    )


def bench_search(engine: AnnotationEngine, args: argparse.Namespace) -> dict[str, Any]:
    vocab = engine.db.vocab
    want = [x for x in ("walk", "run", "wave-right-hand") if x in vocab] or vocab[:3]
    n = 900
    tl = [{"label": want[0], "start": 0, "end": 450}]
    if len(want) > 1:
        tl.append({"label": want[1], "start": 450, "end": n})
    if len(want) > 2:
        tl.append({"label": want[2], "start": 0, "end": n, "value": -1})
    req = AnnotationRequest(frames=n, timeline=tl, seed=1, footskate=False)
    state = AnnotationSearch(engine.db, req)
    state.one_pass()  # warm-up
    times = []
    for _ in range(args.repeats):
        t0 = time.perf_counter()
        state.one_pass()
        times.append(time.perf_counter() - t0)
    rec = CollectingEmitter()
    t0 = time.perf_counter()
    engine.search(req, args.budget, rec, lambda: False)
    wall = time.perf_counter() - t0
    state2 = AnnotationSearch(engine.db, req)
    t0 = time.perf_counter()
    passes = 0
    while time.perf_counter() - t0 < args.budget:
        state2.one_pass()
        passes += 1
    return {
        "output_frames": n,
        "pass_ms_median": round(1e3 * float(np.median(times)), 1),
        "pass_ms_min": round(1e3 * float(np.min(times)), 1),
        "anytime_budget_s": args.budget,
        "anytime_solutions": len(rec.solutions),
        "anytime_solutions_per_s": round(len(rec.solutions) / wall, 2),
        "passes_per_s": round(passes / (time.perf_counter() - t0), 2),
    }


def bench_propagation(args: argparse.Namespace) -> dict[str, Any]:
    items = files(["2"])
    truth = [lab for _, lab in items]
    lib, _ = load(items, set())
    spec = AnnotatedDatabaseSpec(clips=[{"bvh": Path(f).name} for f, _ in items])
    emb, _, _, _ = embed_library(lib, spec)
    z = standardize(emb, SVM_DIMS)
    counts = [m.num_frames for m in lib.motions]
    clip_of = np.repeat(np.arange(len(counts)), counts)
    truth_f = np.repeat(np.array(truth), counts)
    out: dict[str, Any] = {}
    for k in range(1, 6):
        macros: list[float] = []
        clip_acc: list[float] = []
        per: list[dict[str, float]] = []
        for trial in range(args.trials):
            labelled = pick_labelled(truth, k, np.random.default_rng(100 * k + trial))
            labels = [
                [{"label": truth[i], "start": 0, "end": counts[i], "value": 1}] if i in labelled else []
                for i in range(len(items))
            ]
            prop = propagate(z, clip_of, counts, labels, c=spec.svm_c, gammas=spec.gammas, smooth_frames=7)
            held = np.repeat(np.array([i not in labelled for i in range(len(items))]), counts)
            f1 = f1_table(prop.vocab, prop.labels, truth_f, held)
            per.append(f1)
            macros.append(float(np.mean(list(f1.values()))))
            held_clips = {i for i in range(len(items)) if i not in labelled}
            clip_acc.append(clip_accuracy(prop.vocab, prop.labels, counts, truth, held_clips))
        labs = sorted(per[0])
        out[str(k)] = {
            "macro_f1": round(float(np.mean(macros)), 4),
            "clip_accuracy": round(float(np.mean(clip_acc)), 4),
            "per_label": {lab: round(float(np.mean([p[lab] for p in per if lab in p])), 4) for lab in labs},
        }
    return {
        "dataset": "bandai-namco dataset-2",
        "clips": len(items),
        "trials": args.trials,
        "by_labelled_clips": out,
    }


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--part", default="all", choices=["all", "build", "search", "propagation"])
    ap.add_argument("--datasets", default="1,2")
    ap.add_argument("--labelled", type=int, default=3)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--budget", type=float, default=5.0)
    ap.add_argument("--trials", type=int, default=2)
    args = ap.parse_args()
    if not DATA.is_dir():
        print(json.dumps({"skipped": f"no data at {DATA}"}))
        return
    result: dict[str, Any] = {"bench": "annotations"}
    if args.part in ("all", "build", "search"):
        build, engine = bench_build(args)
        result["build"] = build
        if args.part in ("all", "search"):
            result["search"] = bench_search(engine, args)
    if args.part in ("all", "propagation"):
        result["propagation"] = bench_propagation(args)
    print(json.dumps(result))


if __name__ == "__main__":
    main()
