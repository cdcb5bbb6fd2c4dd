"""Label propagation by support vector machines (Arikan, Forsyth & O'Brien 2003, Sec. 3.1).

Each label of the (free) vocabulary partitions the annotated frames into those that carry it (+1)
and those that do not (-1). One RBF SVM per label (scikit-learn's ``SVC``, libsvm as in the
paper), trained on the window embeddings of the annotated frames
(:func:`engines.annotations.features.window_embedding`), classifies every frame the user did not
annotate. The out-of-margin cost ``C`` is high (a tight fit, as in the paper); the kernel width
``gamma`` is chosen per label by cross-validation grouped by clip (neighbouring frames of one clip
are near duplicates, so frame-level folds would overstate accuracy), maximising F1; the chosen
gamma's pooled out-of-fold precision and recall are reported.

Choices the paper leaves open (see :class:`schemas.annotations.AnnotatedDatabaseSpec`):

* which frames are annotated: a ``value: 1`` range annotates its frames fully (they carry that
  label and none of the others unless another range says so); a ``value: -1`` range annotates its
  frames for that label only.
* training frames are subsampled evenly (at most ``max_train_frames`` per label, half of them
  positives when there are enough), with balanced class weights; cross-validation runs on at most
  ``cv_frames`` of them.
* decision values are averaged over ``smooth_s`` within each clip before taking the sign, which
  removes single-frame flicker at the edges of actions.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt
from sklearn.svm import SVC

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.intp]
Int8Array = npt.NDArray[np.int8]
BoolArray = npt.NDArray[np.bool_]


def vocabulary(labels: Sequence[Sequence[dict[str, Any]]]) -> list[str]:
    """The labels used by any clip, in order of first appearance."""
    seen: dict[str, None] = {}
    for clip in labels:
        for lb in clip:
            seen.setdefault(str(lb["label"]), None)
    return list(seen)


def known_labels(
    labels: Sequence[Sequence[dict[str, Any]]], counts: Sequence[int], vocab: Sequence[str]
) -> tuple[Int8Array, BoolArray]:
    """Per database frame (clips end to end) and label: the user's value and whether it is known.

    Ranges are in frames at the database rate, ``[start, end)``, clamped to the clip.

    Returns
    -------
    values: ``(F, L)`` int8, +1 / -1 where known, 0 elsewhere.
    known: ``(F, L)`` bool.
    """
    col = {name: i for i, name in enumerate(vocab)}
    total = int(sum(counts))
    values = np.zeros((total, len(vocab)), dtype=np.int8)
    known = np.zeros((total, len(vocab)), dtype=bool)
    offset = 0
    for clip, n in zip(labels, counts, strict=True):
        full = np.zeros(n, dtype=bool)
        for lb in clip:
            if int(lb.get("value", 1)) == 1:
                full[min(int(lb["start"]), n) : min(int(lb["end"]), n)] = True
        rows = slice(offset, offset + n)
        known[rows][full] = True
        values[rows][full] = -1
        for lb in clip:  # later ranges override earlier ones
            s, e = min(int(lb["start"]), n), min(int(lb["end"]), n)
            j = col[str(lb["label"])]
            values[offset + s : offset + e, j] = int(lb.get("value", 1))
            known[offset + s : offset + e, j] = True
        offset += n
    return values, known


@dataclass(slots=True)
class LabelModel:
    """The outcome of training one label's SVM (what the build reports)."""

    label: str
    status: str  # "trained" | "no positives" | "no negatives"
    positives: int = 0
    negatives: int = 0
    train_frames: int = 0
    gamma: float | None = None
    cv: dict[str, float | None] = field(default_factory=dict)
    support_vectors: int = 0

    def to_json(self) -> dict[str, Any]:
        return {
            "label": self.label,
            "status": self.status,
            "positives": self.positives,
            "negatives": self.negatives,
            "train_frames": self.train_frames,
            "gamma": self.gamma,
            "cv": self.cv,
            "support_vectors": self.support_vectors,
        }


def _even_pick(idx: IntArray, k: int) -> IntArray:
    if idx.size <= k:
        return idx
    return idx[np.linspace(0, idx.size - 1, k).round().astype(np.intp)]


def training_frames(values: Int8Array, known: BoolArray, max_frames: int) -> IntArray:
    """Evenly spread training frames of one label: ``(N,)`` database frames, at most ``max_frames``,
    at least half positives when there are that many."""
    pos = np.flatnonzero(known & (values > 0))
    neg = np.flatnonzero(known & (values < 0))
    k_pos = min(pos.size, max(max_frames // 2, max_frames - neg.size))
    k_neg = min(neg.size, max_frames - k_pos)
    return np.sort(np.concatenate((_even_pick(pos, k_pos), _even_pick(neg, k_neg))))


def _scores(y: Int8Array, pred: Int8Array) -> dict[str, float | None]:
    tp = float(np.sum((pred > 0) & (y > 0)))
    fp = float(np.sum((pred > 0) & (y < 0)))
    fn = float(np.sum((pred < 0) & (y > 0)))
    precision = tp / (tp + fp) if tp + fp else 0.0
    recall = tp / (tp + fn) if tp + fn else 0.0
    f1 = 2 * precision * recall / (precision + recall) if precision + recall else 0.0
    return {"precision": precision, "recall": recall, "f1": f1}


def cross_validate(
    x: FloatArray, y: Int8Array, groups: IntArray, gammas: Sequence[float], c: float, folds: int
) -> tuple[float | None, dict[str, float | None]]:
    """Pick gamma by grouped cross-validation (pooled out-of-fold F1).

    Returns the best gamma and its pooled precision / recall / F1 (``(None, {})`` when the frames
    come from fewer than two clips or a fold lacks a class)."""
    uniq = np.unique(groups)
    if uniq.size < 2:
        return None, {}
    k = min(folds, int(uniq.size))
    # assign whole clips to folds, round robin over clips sorted by id (deterministic)
    fold_of_group = {int(g): i % k for i, g in enumerate(uniq)}
    fold = np.array([fold_of_group[int(g)] for g in groups])
    best: tuple[float, float, dict[str, float | None]] | None = None
    for gamma in gammas:
        pred = np.zeros_like(y)
        ok = True
        for f in range(k):
            tr, te = fold != f, fold == f
            if np.unique(y[tr]).size < 2:
                ok = False
                break
            model = SVC(C=c, kernel="rbf", gamma=gamma, class_weight="balanced")
            model.fit(x[tr], y[tr])
            pred[te] = model.predict(x[te])
        if not ok:
            return None, {}
        s = _scores(y, pred)
        f1 = float(s["f1"] or 0.0)
        if best is None or f1 > best[0] + 1e-9:
            best = (f1, gamma, s)
    assert best is not None
    return best[1], best[2]


def smooth_within_clips(x: FloatArray, counts: Sequence[int], window: int) -> FloatArray:
    """Centred moving average ``(F, ...)`` of ``window`` frames (odd), never across clips."""
    if window <= 1:
        return x
    out = np.empty_like(x)
    half = window // 2
    offset = 0
    for n in counts:
        seg = x[offset : offset + n]
        pad = np.pad(seg, [(half, half)] + [(0, 0)] * (x.ndim - 1), mode="edge")
        c = np.cumsum(pad, axis=0)
        c = np.concatenate((np.zeros((1, *seg.shape[1:])), c), axis=0)
        out[offset : offset + n] = (c[2 * half + 1 :] - c[: -2 * half - 1]) / (2 * half + 1)
        offset += n
    return out


def strided_decision(
    model: SVC,
    embedding: FloatArray,
    clip_of_frame: IntArray,
    counts: Sequence[int],
    frames: IntArray,
    step: int,
) -> npt.NDArray[np.float32]:
    """``(len(frames),)`` SVM decision values at database ``frames``, computed on every ``step``-th
    frame of their clips (and each clip's last frame) and linearly interpolated in between."""
    if step <= 1:
        return np.asarray(model.decision_function(embedding[frames]), dtype=np.float32)
    c = np.asarray(counts, dtype=np.intp)
    start = np.concatenate(([0], np.cumsum(c)[:-1]))
    clip = clip_of_frame[frames]
    local = frames - start[clip]
    last = c[clip] - 1
    left = np.minimum((local // step) * step, last)
    right = np.minimum(left + step, last)
    need = np.unique(np.concatenate((start[clip] + left, start[clip] + right)))
    values = np.asarray(model.decision_function(embedding[need]), dtype=np.float64)
    at = np.searchsorted(need, start[clip] + left)
    bt = np.searchsorted(need, start[clip] + right)
    span = np.maximum(right - left, 1)
    w = (local - left) / span
    return np.asarray((1 - w) * values[at] + w * values[bt], dtype=np.float32)


@dataclass(slots=True)
class Propagation:
    """Result of :func:`propagate`: per database frame and label."""

    vocab: list[str]
    labels: Int8Array  # (F, L) +1 / -1
    known: BoolArray  # (F, L) user-given
    decision: npt.NDArray[np.float32]  # (F, L) smoothed SVM decision values (+-1 where known)
    models: list[LabelModel]

    def report_json(self) -> str:
        return json.dumps([m.to_json() for m in self.models])


def propagate(
    embedding: FloatArray,
    clip_of_frame: IntArray,
    counts: Sequence[int],
    labels: Sequence[Sequence[dict[str, Any]]],
    *,
    c: float = 100.0,
    gammas: Sequence[float] = (0.25, 0.5, 1.0, 2.0),
    folds: int = 3,
    max_train_frames: int = 2000,
    cv_frames: int = 1200,
    smooth_frames: int = 1,
    step: int = 1,
    progress: Callable[[float, str], None] | None = None,
    should_stop: Callable[[], bool] | None = None,
) -> Propagation:
    """Train one SVM per label on the annotated frames and label every other frame.

    Parameters
    ----------
    embedding: ``(F, E)`` standardized window embeddings of every database frame.
    clip_of_frame: ``(F,)`` clip index of each frame; ``counts`` the clips' frame counts.
    labels: per clip, its label ranges (``{label, start, end, value}``, database frames).
    gammas: grid of multiples of ``1 / total variance of the embedding``.
    smooth_frames: moving-average width of the decision values (odd frames; 1 = none).
    step: classify every ``step``-th frame of a clip (and its last) and interpolate the decision
        values linearly in between (the window embedding changes slowly; 1 = every frame).
    """
    vocab = vocabulary(labels)
    values, known = known_labels(labels, counts, vocab)
    out = values.copy()
    decision = values.astype(np.float32)
    scale = 1.0 / max(float(embedding.var(axis=0).sum()), 1e-12)
    grid = [g * scale for g in gammas]
    models: list[LabelModel] = []
    for j, name in enumerate(vocab):
        if should_stop is not None and should_stop():
            raise InterruptedError("stopped")
        v, k = values[:, j], known[:, j]
        n_pos, n_neg = int(np.sum(k & (v > 0))), int(np.sum(k & (v < 0)))
        unknown = np.flatnonzero(~k)
        if n_pos == 0 or n_neg == 0:
            status = "no positives" if n_pos == 0 else "no negatives"
            out[unknown, j] = -1 if n_pos == 0 else 1
            decision[unknown, j] = float(out[unknown[:1], j][0]) if unknown.size else 0.0
            models.append(LabelModel(name, status, n_pos, n_neg))
        else:
            train = training_frames(v, k, max_train_frames)
            cv_idx = train[_even_pick(np.arange(train.size), cv_frames)]
            gamma, cv = cross_validate(embedding[cv_idx], v[cv_idx], clip_of_frame[cv_idx], grid, c, folds)
            gamma = grid[len(grid) // 2] if gamma is None else gamma
            model = SVC(C=c, kernel="rbf", gamma=gamma, class_weight="balanced")
            model.fit(embedding[train], v[train])
            if unknown.size:
                decision[unknown, j] = strided_decision(
                    model, embedding, clip_of_frame, counts, unknown, step
                )
            models.append(
                LabelModel(
                    name,
                    "trained",
                    n_pos,
                    n_neg,
                    int(train.size),
                    float(gamma / scale),
                    cv,
                    int(model.support_.size),
                )
            )
        if progress is not None:
            m = models[-1]
            cv_txt = (
                f"cv precision {m.cv['precision']:.2f} recall {m.cv['recall']:.2f}"
                if m.cv
                else "cv n/a (needs 2+ labelled clips)"
            )
            progress((j + 1) / max(len(vocab), 1), f"label {name!r}: {m.status}, {cv_txt}")
    if smooth_frames > 1 and vocab:
        smoothed = smooth_within_clips(decision.astype(np.float64), counts, smooth_frames)
        decision = np.where(known, values, smoothed).astype(np.float32)
        pred = np.where(smoothed >= 0, 1, -1).astype(np.int8)
        out = np.where(known, values, pred).astype(np.int8)
    else:
        out = np.where(known, values, np.where(decision >= 0, 1, -1)).astype(np.int8)
    return Propagation(vocab, out, known, decision, models)
