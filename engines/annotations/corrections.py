"""The correction loop (Arikan, Forsyth & O'Brien 2003, Sec. 3.1): user-verified labels join the
training set and the database is rebuilt.

A database is content-addressed by its spec, so a correction is a *new spec*: the corrected ranges
are written into the clips' ``labels`` (:func:`apply_corrections`), and building that spec
retrains the SVMs with the corrections among the annotated frames (same pipeline, new database
id). The flow:

1. build ``spec`` -> database ``D`` (propagated labels in ``ann.labels``; the build's progress
   messages and ``ann.report`` give each label's cross-validated precision / recall);
2. look at a clip's propagated labels (:func:`propagated_ranges` on ``D``'s label table,
   :class:`~engines.annotations.labels.LabelTable`, read from a few small arrays), then either
   *accept* a range (its propagated labels become explicit: every vocabulary label, +1 and -1) or
   *set* a label on a range (replacing that label's ranges there);
3. ``apply_corrections(spec, corrections, D)`` -> ``spec'``; build ``spec'`` -> ``D'``.

From the command line::

    python -m engines.annotations.corrections SPEC.json --db DIR --corrections FIXES.json --out NEW.json
    segue build NEW.json --out DIR2

``FIXES.json`` is a list of :class:`schemas.annotations.LabelCorrection`, e.g.
``[{"clip": "b", "start": 0, "end": 90, "action": "accept"},
{"clip": "b", "start": 90, "end": 140, "label": "wave-right-hand", "value": 1}]``.
A ``set`` with value 1 annotates its frames fully (they then carry no other label unless another
range says so): accept a range first to keep its other propagated labels.
"""

from __future__ import annotations

import argparse
import itertools
import json
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from motion.mirror import mirror_label
from schemas.annotations import AnnotatedDatabaseSpec, LabelCorrection

from ..base import EngineError, open_database
from ..library import MIRROR_SUFFIX
from .labels import LabelTable


def _runs(values: npt.NDArray[np.int8], start: int) -> list[tuple[int, int, int]]:
    """``(start, end, value)`` runs of equal values, frames offset by ``start``."""
    change = np.flatnonzero(np.diff(values)) + 1
    edges = np.concatenate(([0], change, [values.size]))
    return [(start + int(a), start + int(b), int(values[a])) for a, b in itertools.pairwise(edges)]


def propagated_ranges(
    table: LabelTable, clip: str, start: int = 0, end: int | None = None
) -> list[dict[str, Any]]:
    """The database's labels of frames ``[start, end)`` of ``clip`` as explicit ranges (every
    vocabulary label, value +1 or -1), in database frames."""
    c = table.clip_index(clip)
    g0, n = int(table.clip_start[c]), int(table.counts[c])
    end = n if end is None else min(end, n)
    if not 0 <= start < end:
        raise EngineError(f"clip {clip!r}: empty range {start}:{end} (the clip has {n} frames)")
    out = []
    for j, label in enumerate(table.vocab):
        for a, b, v in _runs(table.labels[g0 + start : g0 + end, j], start):
            out.append({"label": label, "start": a, "end": b, "value": v})
    return out


def _set_range(
    labels: list[dict[str, Any]], label: str, start: int, end: int, value: int
) -> list[dict[str, Any]]:
    """``labels`` with ``label``'s ranges cut out of ``[start, end)`` and the new range added."""
    out = []
    for lb in labels:
        if lb["label"] != label or lb["end"] <= start or lb["start"] >= end:
            out.append(lb)
            continue
        if lb["start"] < start:
            out.append({**lb, "end": start})
        if lb["end"] > end:
            out.append({**lb, "start": end})
    out.append({"label": label, "start": start, "end": end, "value": value})
    return out


def _spec_clip(clip: str, names: list[str], refs: list[str], mirror: bool) -> tuple[int, bool]:
    """The spec clip a correction on ``clip`` changes and whether ``clip`` is its mirror image
    (with ``mirror``, ``'<clip> (mirror)'``: its labels are its clip's, sides exchanged, so a
    correction on it is its clip's correction mirrored)."""
    for candidates in (names, refs):
        if clip in candidates:
            return candidates.index(clip), False
    source = clip.removesuffix(MIRROR_SUFFIX)
    if mirror and source != clip:
        for candidates in (names, refs):
            if source in candidates:
                return candidates.index(source), True
    raise EngineError(f"no clip named {clip!r} in the spec")


def apply_corrections(
    spec: AnnotatedDatabaseSpec, corrections: list[LabelCorrection], db: LabelTable | None = None
) -> AnnotatedDatabaseSpec:
    """A new spec whose clips carry the corrected label ranges (build it to retrain).

    ``accept`` corrections need the built database's label table ``db`` (its propagated labels);
    clips are named as in the database (library name or the spec's reference). With the spec's
    ``mirror``, a correction on a mirror image ``'<clip> (mirror)'`` corrects ``<clip>``, the sides
    its labels name exchanged (:func:`motion.mirror.mirror_label`): the same frames, since a mirror
    image keeps its clip's timing."""
    names = [c.display_name() for c in spec.clips]
    refs = [c.name or c.bvh or c.clip or n for c, n in zip(spec.clips, names, strict=True)]
    clips = [c.model_dump(mode="json", exclude_none=True) for c in spec.clips]
    for fix in corrections:
        i, mirrored = _spec_clip(fix.clip, names, refs, spec.mirror)
        side = mirror_label if mirrored else str
        labels = list(clips[i].get("labels", []))
        if fix.action == "accept":
            if db is None:
                raise EngineError("accepting propagated labels needs the built database")
            for r in propagated_ranges(db, fix.clip, fix.start, fix.end):
                labels = _set_range(labels, side(r["label"]), r["start"], r["end"], r["value"])
        elif fix.label is None:
            raise EngineError(f"the 'set' correction on {fix.clip!r} names no label")
        else:
            labels = _set_range(labels, side(fix.label), fix.start, fix.end, fix.value)
        clips[i]["labels"] = sorted(labels, key=lambda lb: (lb["start"], lb["label"]))
    data = spec.model_dump(mode="json", exclude_none=True)
    data["clips"] = clips
    return AnnotatedDatabaseSpec.model_validate(data)


def main(argv: list[str] | None = None) -> int:
    """``python -m engines.annotations.corrections SPEC --db DIR --corrections FIXES --out NEW``."""
    ap = argparse.ArgumentParser(description="Write a corrected annotated database spec.")
    ap.add_argument("spec", type=Path)
    ap.add_argument("--db", type=Path, help="built database directory (needed for 'accept')")
    ap.add_argument("--corrections", type=Path, required=True)
    ap.add_argument("--out", type=Path, required=True)
    args = ap.parse_args(argv)
    spec = AnnotatedDatabaseSpec.model_validate_json(args.spec.read_bytes())
    fixes = [LabelCorrection.model_validate(x) for x in json.loads(args.corrections.read_text())]
    db = None
    if args.db is not None:
        with open_database(args.db / "data.npz") as arrays:
            db = LabelTable.read(arrays)
    new = apply_corrections(spec, fixes, db)
    args.out.write_text(new.model_dump_json(indent=2, exclude_none=True))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
