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
* decision values are averaged over ``smooth_s`` within each clip before labelling, which
  removes single-frame flicker at the edges of actions.

Four additions in the paper's spirit (``exclusive``, ``switch_s``, ``self_training`` and
``refine_changes`` in the spec; each can be turned off):

* **exclusive labels**: labels never annotated on the same frame are taken to exclude each other.
  The allowed label sets are the cliques of the co-occurrence graph (:func:`label_states`: each
  label alone, walk + wave when some frame carries both, ...), and every frame gets the set whose
  signs agree best with all the SVMs' decision values, instead of each label thresholding its
  own uncalibrated SVM (which leaves frames with no label or two exclusive ones).
* **temporal consistency**: the sets are chosen per clip by dynamic programming
  (:func:`viterbi`) with a cost per change, so a clip changes labels where the evidence for the
  change outweighs the cost, not at every ambiguous frame.
* **self-training** (transductive): the most confident propagated frames of each label set join
  the training set with a lower weight, the SVMs retrain with the same gamma, and every frame is
  labelled again (:func:`pseudo_labels`).
* **sharp changes** (``refine_changes``): the context window that labels whole actions well
  blurs where a label changes inside a clip, so, given the fine window's embedding alone
  (:class:`SvmEmbedding`), a second SVM per label trained on it places every change again
  (:func:`refine_changes`).

The stored decision value of a propagated label is its signed confidence: half the per-frame
score lost by flipping it (``|d|`` of its SVM when labels are independent).
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from itertools import pairwise
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


def cooccurrence(values: Int8Array, known: BoolArray) -> BoolArray:
    """``(L, L)`` whether two labels are both +1 on some user-annotated frame (the diagonal: whether
    a label has any positive frame)."""
    pos = (known & (values > 0)).astype(np.float64)
    return np.asarray(pos.T @ pos > 0)


def label_states(values: Int8Array, known: BoolArray, max_states: int = 512) -> Int8Array | None:
    """The label combinations propagation may assign, as ``(S, L)`` +1 / -1 rows.

    Labels that never co-occur on an annotated frame are taken as mutually exclusive, so the
    states are the cliques of the co-occurrence graph (:func:`cooccurrence`): every label alone,
    every co-occurring pair (e.g. walk + wave), and so on, plus the empty state (no label), last:
    a frame that no SVM claims (every decision value negative) stays unlabelled rather than being
    forced into the least unlikely label, so motion unlike anything labelled (a kick among walks
    and runs) is not offered to the search as one of them. ``None`` when no label has a positive
    frame or there are more than ``max_states`` cliques (then labels are decided independently)."""
    co = cooccurrence(values, known)
    n = co.shape[0]
    cliques: list[list[int]] = []

    def grow(current: list[int], candidates: list[int]) -> bool:
        for i, j in enumerate(candidates):
            clique = [*current, j]
            cliques.append(clique)
            if len(cliques) > max_states:
                return False
            if not grow(clique, [k for k in candidates[i + 1 :] if co[j, k]]):
                return False
        return True

    if not grow([], [j for j in range(n) if co[j, j]]) or not cliques:
        return None
    states = -np.ones((len(cliques) + 1, n), dtype=np.int8)
    for s, clique in enumerate(cliques):
        states[s, clique] = 1
    return states


def viterbi(score: FloatArray, counts: Sequence[int], switch_cost: float, batch: int = 64) -> IntArray:
    """Per clip, the state sequence maximizing the summed per-frame ``score`` ``(F, S)`` minus
    ``switch_cost`` per change of state; returns ``(F,)`` state indices.

    Clips are processed in batches of similar length (vectorized over clips and states)."""
    f_total, n_states = score.shape
    out = np.zeros(f_total, dtype=np.intp)
    if f_total == 0:
        return out
    c = np.asarray(counts, dtype=np.intp)
    start = np.concatenate(([0], np.cumsum(c)[:-1]))
    order = np.argsort(c, kind="stable")
    order = order[c[order] > 0]
    ar = np.arange(n_states)
    for b in range(0, order.size, batch):
        clips = order[b : b + batch]
        n = c[clips]
        first = start[clips]
        t_max = int(n.max())
        acc = score[first].copy()  # (B, S)
        back = np.zeros((t_max, clips.size, n_states), dtype=np.int32)
        for t in range(1, t_max):
            live = t < n
            best = acc.argmax(axis=1)
            jump = acc[np.arange(clips.size), best] - switch_cost
            stay = acc >= jump[:, None]
            back[t] = np.where(stay, ar[None, :], best[:, None])
            rows = np.minimum(first + t, f_total - 1)
            new = np.maximum(acc, jump[:, None]) + score[rows]
            acc = np.where(live[:, None], new, acc)
        state = acc.argmax(axis=1)
        for t in range(t_max - 1, -1, -1):
            ends = np.flatnonzero(t < n)
            out[first[ends] + t] = state[ends]
            if t:
                state[ends] = back[t, ends, state[ends]]
    return out


def change_windows(pick: IntArray, counts: Sequence[int], reach: int) -> BoolArray:
    """``(F,)`` frames within ``2 * reach`` frames of a change of state ``pick`` ``(F,)`` inside a
    clip: the frames whose fine-window scores :func:`refine_changes` reads."""
    near = np.zeros(pick.size, dtype=bool)
    if reach <= 0 or pick.size == 0:
        return near
    c = np.asarray(counts, dtype=np.intp)
    ends = np.cumsum(c)
    clip = np.repeat(np.arange(c.size), c)
    change = np.flatnonzero(pick[1:] != pick[:-1]) + 1
    change = change[clip[change] == clip[change - 1]]
    for t in change:
        lo = max(int(ends[clip[t]] - c[clip[t]]), int(t) - 2 * reach)
        hi = min(int(ends[clip[t]]), int(t) + 2 * reach)
        near[lo:hi] = True
    return near


def _runs(pick: IntArray, start: int, end: int) -> list[tuple[int, int, int]]:
    """``(first, stop, state)`` of the runs of equal ``pick`` in frames ``[start, end)``."""
    seg = pick[start:end]
    cut = np.flatnonzero(seg[1:] != seg[:-1]) + 1
    bounds = [0, *cut.tolist(), seg.size]
    return [(start + bounds[i], start + bounds[i + 1], int(seg[bounds[i]])) for i in range(len(bounds) - 1)]


REFINE_AGREE = 2.0 / 3.0
"""Share of each flank's frames on which the fine-window SVMs must side with the decoded state
before they may move a change (:func:`refine_changes`)."""


def refine_changes(
    pick: IntArray,
    fine_score: FloatArray,
    counts: Sequence[int],
    reach: int,
    min_run: int | None = None,
    agree: float = REFINE_AGREE,
) -> IntArray:
    """Re-locate the changes of state inside clips on the evidence of a shorter window.

    Parameters
    ----------
    pick: ``(F,)`` decoded state of each frame (clips end to end, ``counts`` frames each).
    fine_score: ``(F, S)`` per-frame score of each state from fine-window-only SVMs; only the
        frames of :func:`change_windows` are read.
    reach: frames; how far the decoding's (context) window blurs a change, half its width.
    min_run: frames (default ``reach``); shorter runs between two runs of different states are
        taken as the blur of one change (a context window straddling a change matches neither
        action, so the decoding there often says no label, or a third one).
    agree: in ``[0, 1]``; see below.

    A change from state ``a`` to ``b`` (with the short runs in between, from frame ``first`` to
    ``stop``) moves to the frame ``t`` in ``[first - reach, stop + reach]`` maximizing
    ``sum_{f < t} score[f, a] + sum_{f >= t} score[f, b]`` (two states, one change; the short runs
    go), without crossing the neighbouring changes (moved ones on the left, old ones on the
    right; the runs of ``a`` and ``b`` keep at least one frame). It moves only if the fine scores
    prefer ``a`` to ``b`` on at least ``agree`` of the frames between ``2 * reach`` and ``reach``
    before the change, and ``b`` to ``a`` on as many after it (each flank at least one frame of
    its run): beyond the blur the decoding is trusted, so fine SVMs that cannot tell the two
    states apart there (the straight start of a turning walk against a plain walk) do not
    place the change. Returns the refined ``(F,)`` states."""
    if reach < 0:
        raise ValueError(f"reach must be >= 0, got {reach}")
    if not 0.0 <= agree <= 1.0:
        raise ValueError(f"agree must be in [0, 1], got {agree}")
    if fine_score.ndim != 2 or fine_score.shape[0] != pick.size:
        raise ValueError(f"fine_score must be (F, S) with F = {pick.size}, got {fine_score.shape}")
    out = pick.copy()
    if reach == 0 or pick.size == 0:
        return out
    short = reach if min_run is None else min_run
    offset = 0
    for n in counts:
        start, end = offset, offset + int(n)
        offset = end
        runs = _runs(pick, start, end) if n else []
        if len(runs) < 2:
            continue
        last = len(runs) - 1
        kept = [i for i, (a, b, _) in enumerate(runs) if i in (0, last) or b - a >= short]
        # changes to place, as (run before, run after): consecutive kept runs of different states
        # merge the short runs between them; otherwise each change is placed on its own
        steps: list[tuple[int, int]] = []
        for i, k in pairwise(kept):
            if runs[i][2] != runs[k][2]:
                steps.append((i, k))
            else:
                steps.extend((m, m + 1) for m in range(i, k))
        prev = start  # first frame of the run before the next change (after moving)
        for i, k in steps:
            a, b = runs[i][2], runs[k][2]
            first, stop = runs[i][1], runs[k][0]  # frames [first, stop) are the short runs
            lo = max(prev + 1, first - reach)
            hi = min(runs[k][1] - 1, stop + reach)
            l0 = max(prev, first - 2 * reach)
            l1 = max(l0 + 1, first - reach)
            r1 = min(runs[k][1], stop + 2 * reach)
            r0 = min(r1 - 1, stop + reach)
            before = float(np.mean(fine_score[l0:l1, a] > fine_score[l0:l1, b]))
            after = float(np.mean(fine_score[r0:r1, b] > fine_score[r0:r1, a]))
            if hi < lo or min(before, after) < agree:
                prev = stop
                continue
            seg = fine_score[lo - 1 : hi + 1]  # frames lo-1 .. hi
            # change at lo + m: frames lo-1 .. lo+m-1 are a, lo+m .. hi are b
            left = np.cumsum(seg[:, a])
            right = np.cumsum(seg[::-1, b])[::-1]
            best = lo + int(np.argmax(left[:-1] + right[1:]))
            out[lo - 1 : best] = a
            out[best : hi + 1] = b
            prev = best
    return out


def decode(
    decision: FloatArray,
    values: Int8Array,
    known: BoolArray,
    counts: Sequence[int],
    states: Int8Array | None,
    switch_cost: float,
    floor: float = 0.05,
    refine: Callable[[IntArray, FloatArray], IntArray] | None = None,
) -> tuple[Int8Array, FloatArray]:
    """Labels of every frame from the (smoothed) SVM decision values ``(F, L)``.

    With ``states`` (:func:`label_states`) each frame gets one allowed label combination: the
    one whose signs agree best with the decision values (score ``sum_j s_j d_j``), chosen per
    clip by :func:`viterbi` with ``switch_cost`` (decision units x frames) per change, so a clip
    changes labels only where the evidence for the change outweighs the cost. User-given values
    constrain the states of their frames. Without ``states``, each label is the sign of its
    decision value.

    ``refine`` (with ``states``), given the decoded ``(F,)`` state indices and the ``(F, S)``
    penalty of each state for clashing with user-given values, returns the final states (the
    changes re-located by :func:`refine_changes`).

    Returns
    -------
    labels: ``(F, L)`` int8 +1 / -1 (user-given values where known).
    confidence: ``(F, L)`` >= 0: half the per-frame score lost by flipping that label to the best
        state with the other value (``|d_j|`` for independent labels), at least ``floor``.
    """
    if states is None:
        labels = np.where(known, values, np.where(decision >= 0, 1, -1)).astype(np.int8)
        conf = np.maximum(np.abs(decision), floor)
        return labels, np.where(known, 1.0, conf)
    s = states.astype(np.float64)
    score = decision @ s.T  # (F, S)
    penalty = np.zeros_like(score)
    if known.any():
        clash = (known[:, None, :] & (states[None, :, :] != values[:, None, :])).sum(axis=2)
        penalty = 1e6 * clash
        score = score - penalty
    pick = viterbi(score, counts, switch_cost)
    if refine is not None:
        pick = refine(pick, penalty)
    labels = np.where(known, values, states[pick]).astype(np.int8)
    own = score[np.arange(score.shape[0]), pick]
    conf = np.full(decision.shape, floor)
    for j in range(states.shape[1]):
        for sign in (1, -1):
            at = states[pick, j] == sign
            other = states[:, j] != sign
            if not at.any():
                continue
            if other.any():
                alt = score[np.ix_(np.flatnonzero(at), np.flatnonzero(other))].max(axis=1)
                conf[at, j] = np.maximum(0.5 * (own[at] - alt), floor)
            else:  # no state has the other value: as sure as the SVM is
                conf[at, j] = np.maximum(np.abs(decision[at, j]), floor)
    return labels, np.where(known, 1.0, conf)


def pseudo_labels(labels: Int8Array, confidence: FloatArray, known: BoolArray, fraction: float) -> BoolArray:
    """``(F,)`` frames to add to the training set in a self-training round: among frames with no
    user-given value, the most confident ``fraction`` of each assigned label combination (the
    frame's confidence is its least confident label), so that every combination contributes in
    proportion and none takes over."""
    free = ~known.any(axis=1)
    chosen = np.zeros(labels.shape[0], dtype=bool)
    if fraction <= 0 or not free.any():
        return chosen
    conf = confidence.min(axis=1)
    idx = np.flatnonzero(free)
    _, group = np.unique(labels[idx], axis=0, return_inverse=True)
    group = np.asarray(group).reshape(-1)
    for g in np.unique(group):
        members = idx[group == g]
        k = int(round(fraction * members.size))
        if k:
            chosen[members[np.argsort(-conf[members], kind="stable")[:k]]] = True
    return chosen


@dataclass(frozen=True, slots=True)
class SvmEmbedding:
    """The SVM inputs of every database frame.

    ``combined`` ``(F, E)``: the standardized embedding of the fine window plus the coarse context
    (what the label SVMs classify). ``fine`` ``(F, E_f)`` or ``None``: the fine window alone, for
    re-locating label changes (:func:`refine_changes`) within ``reach`` frames (half the context
    window: how far the context blurs a change)."""

    combined: FloatArray
    fine: FloatArray | None = None
    reach: int = 0

    def __post_init__(self) -> None:
        if self.fine is not None and self.fine.shape[0] != self.combined.shape[0]:
            raise ValueError(
                f"fine embedding has {self.fine.shape[0]} frames, combined {self.combined.shape[0]}"
            )
        if self.reach < 0:
            raise ValueError(f"reach must be >= 0, got {self.reach}")


@dataclass(slots=True)
class Propagation:
    """Result of :func:`propagate`: per database frame and label."""

    vocab: list[str]
    labels: Int8Array  # (F, L) +1 / -1
    known: BoolArray  # (F, L) user-given
    decision: npt.NDArray[np.float32]  # (F, L) signed confidence of the labels (+-1 where known)
    models: list[LabelModel]

    def report_json(self) -> str:
        return json.dumps([m.to_json() for m in self.models])


def _fit(
    embedding: FloatArray,
    y: Int8Array,
    frames: IntArray,
    weights: FloatArray,
    c: float,
    gamma: float,
) -> SVC:
    model = SVC(C=c, kernel="rbf", gamma=gamma, class_weight="balanced")
    model.fit(embedding[frames], y[frames], sample_weight=weights)
    return model


def propagate(
    embedding: FloatArray | SvmEmbedding,
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
    exclusive: bool = True,
    switch_cost: float = 0.0,
    self_training: int = 0,
    pseudo_fraction: float = 0.5,
    pseudo_weight: float = 0.5,
    progress: Callable[[float, str], None] | None = None,
    should_stop: Callable[[], bool] | None = None,
) -> Propagation:
    """Train one SVM per label on the annotated frames and label every other frame.

    Parameters
    ----------
    embedding: ``(F, E)`` standardized window embeddings of every database frame, or an
        :class:`SvmEmbedding`; when it has a ``fine`` part (and ``exclusive``), one more SVM per
        label is trained on the fine window alone (same training frames, the same gamma multiple)
        and every label change inside a clip is re-located on its decision values within
        ``reach`` frames (:func:`refine_changes`).
    clip_of_frame: ``(F,)`` clip index of each frame; ``counts`` the clips' frame counts.
    labels: per clip, its label ranges (``{label, start, end, value}``, database frames).
    gammas: grid of multiples of ``1 / total variance of the embedding``.
    smooth_frames: moving-average width of the decision values (odd frames; 1 = none).
    step: classify every ``step``-th frame of a clip (and its last) and interpolate the decision
        values linearly in between (the window embedding changes slowly; 1 = every frame).
    exclusive: labels that never co-occur on an annotated frame exclude each other; every frame
        gets the allowed combination that best fits all the SVMs (:func:`decode`), else each label
        is the sign of its own SVM.
    switch_cost: with ``exclusive``, the cost (decision units x frames) of a change of labels
        within a clip; 0 decides every frame on its own.
    self_training: rounds of transductive self-training: the most confident ``pseudo_fraction``
        of the propagated frames of each label combination join the training set with weight
        ``pseudo_weight`` (the user's frames weigh 1), the SVMs retrain (same gamma) and the
        frames are labelled again.
    """
    params = _PropagationParams(
        c,
        folds,
        max_train_frames,
        cv_frames,
        smooth_frames,
        step,
        switch_cost,
        pseudo_fraction,
        pseudo_weight,
    )
    p = _Propagator(embedding, clip_of_frame, counts, labels, exclusive, params, progress, should_stop)
    rounds = 1 + max(int(self_training), 0)
    p.total_steps = max(len(p.vocab) * rounds, 1)
    grid = [g * p.scale for g in gammas]
    for j, name in enumerate(p.vocab):
        p.check_stop()
        p.train_label(j, grid)
        m = p.models[-1]
        cv_txt = (
            f"cv precision {m.cv['precision']:.2f} recall {m.cv['recall']:.2f}"
            if m.cv
            else "cv n/a (needs 2+ labelled clips)"
        )
        p.step_done(j + 1, f"label {name!r}: {m.status}, {cv_txt}")
    out, conf = p.label_frames()
    for r in range(1, rounds):
        chosen = pseudo_labels(out, conf, p.known, pseudo_fraction)
        if not chosen.any():
            break
        p.self_train_round(r, out, chosen)
        out, conf = p.label_frames()
    signed = np.where(p.known, p.values, out * conf).astype(np.float32)
    return Propagation(p.vocab, out, p.known, signed, p.models)


@dataclass(frozen=True, slots=True)
class _PropagationParams:
    """The settings of :func:`propagate` the steps share (see its parameters)."""

    c: float
    folds: int
    max_train_frames: int
    cv_frames: int
    smooth_frames: int
    step: int
    switch_cost: float
    pseudo_fraction: float
    pseudo_weight: float


class _Propagator:
    """The state of one :func:`propagate`: the user's labels, every label's SVM and the decision
    values of every frame (Sec. 3.1), refined and decoded into labels."""

    def __init__(
        self,
        embedding: FloatArray | SvmEmbedding,
        clip_of_frame: IntArray,
        counts: Sequence[int],
        labels: Sequence[Sequence[dict[str, Any]]],
        exclusive: bool,
        params: _PropagationParams,
        progress: Callable[[float, str], None] | None,
        should_stop: Callable[[], bool] | None,
    ) -> None:
        if isinstance(embedding, SvmEmbedding):
            self.fine_emb, self.reach = embedding.fine, embedding.reach
            embedding = embedding.combined
        else:
            self.fine_emb, self.reach = None, 0
        self.embedding, self.clip_of_frame, self.counts = embedding, clip_of_frame, counts
        self.params, self.progress, self.should_stop = params, progress, should_stop
        self.vocab = vocabulary(labels)
        self.values, self.known = known_labels(labels, counts, self.vocab)
        self.decision = self.values.astype(np.float64)  # (F, L) the SVMs' decision values
        self.scale = 1.0 / max(float(embedding.var(axis=0).sum()), 1e-12)
        self.states = label_states(self.values, self.known) if exclusive else None
        self.refining = self.fine_emb is not None and self.reach > 0 and self.states is not None
        self.fine_scale = (
            1.0 / max(float(self.fine_emb.var(axis=0).sum()), 1e-12) if self.fine_emb is not None else 1.0
        )
        self.fine_models: list[SVC | None] = []
        self.models: list[LabelModel] = []
        self.fitted: list[tuple[SVC, float] | None] = []
        self.fine_decision = np.where(self.known, self.values, 0.0)
        self.fine_done: BoolArray = np.asarray(self.known.all(axis=1), dtype=bool)
        self.total_steps = 1

    def check_stop(self) -> None:
        if self.should_stop is not None and self.should_stop():
            raise InterruptedError("stopped")

    def step_done(self, done: int, message: str) -> None:
        if self.progress is not None:
            self.progress(done / self.total_steps, message)

    def train_label(self, j: int, grid: list[float]) -> None:
        """Label ``j``'s SVM: gamma by cross-validation over ``grid``, trained on the user's frames,
        deciding every other frame (a label without positives or negatives decides them all)."""
        pr, name = self.params, self.vocab[j]
        v, k = self.values[:, j], self.known[:, j]
        n_pos, n_neg = int(np.sum(k & (v > 0))), int(np.sum(k & (v < 0)))
        unknown = np.flatnonzero(~k)
        if n_pos == 0 or n_neg == 0:
            status = "no positives" if n_pos == 0 else "no negatives"
            self.decision[unknown, j] = -1.0 if n_pos == 0 else 1.0
            self.models.append(LabelModel(name, status, n_pos, n_neg))
            self.fitted.append(None)
            self.fine_models.append(None)
            return
        train = training_frames(v, k, pr.max_train_frames)
        cv_idx = train[_even_pick(np.arange(train.size), pr.cv_frames)]
        emb = self.embedding
        gamma, cv = cross_validate(emb[cv_idx], v[cv_idx], self.clip_of_frame[cv_idx], grid, pr.c, pr.folds)
        gamma = grid[len(grid) // 2] if gamma is None else gamma
        model = _fit(emb, v, train, np.ones(train.size), pr.c, gamma)
        if self.refining and self.fine_emb is not None:
            fine_gamma = gamma / self.scale * self.fine_scale
            self.fine_models.append(_fit(self.fine_emb, v, train, np.ones(train.size), pr.c, fine_gamma))
        if unknown.size:
            self.decision[unknown, j] = strided_decision(
                model, emb, self.clip_of_frame, self.counts, unknown, pr.step
            )
        self.models.append(
            LabelModel(
                name,
                "trained",
                n_pos,
                n_neg,
                int(train.size),
                float(gamma / self.scale),
                cv,
                int(model.support_.size),
            )
        )
        self.fitted.append((model, gamma))

    def refine(self, pick: IntArray, penalty: FloatArray) -> IntArray:
        """Re-locate every label change of ``pick`` on the fine SVMs' decision values (computed
        once per frame, near changes only)."""
        if self.fine_emb is None or self.states is None:
            raise ValueError("refining needs the fine embedding and the label states")
        need = change_windows(pick, self.counts, self.reach) & ~self.fine_done
        rows = np.flatnonzero(need)
        if rows.size:
            for j, fm in enumerate(self.fine_models):
                free = rows[~self.known[rows, j]]
                if fm is None:
                    self.fine_decision[free, j] = self.decision[free, j]
                elif free.size:
                    self.fine_decision[free, j] = fm.decision_function(self.fine_emb[free])
            self.fine_done[rows] = True
        fine_score = self.fine_decision @ self.states.T.astype(np.float64) - penalty
        return refine_changes(pick, fine_score, self.counts, self.reach)

    def label_frames(self) -> tuple[Int8Array, FloatArray]:
        """Every frame's labels and their confidence from the smoothed decision values (the user's
        labels kept)."""
        raw = self.decision
        smoothed = smooth_within_clips(raw, self.counts, self.params.smooth_frames) if self.vocab else raw
        smoothed = np.where(self.known, self.values, smoothed)
        return decode(
            smoothed,
            self.values,
            self.known,
            self.counts,
            self.states,
            self.params.switch_cost,
            refine=self.refine if self.refining else None,
        )

    def self_train_round(self, r: int, out: Int8Array, chosen: BoolArray) -> None:
        """Round ``r`` of self-training: each trained label's SVM retrains (same gamma) on the
        user's frames and the ``chosen`` propagated ones (weight ``pseudo_weight``), deciding the
        unknown frames again."""
        pr, n_labels = self.params, len(self.vocab)
        for j, name in enumerate(self.vocab):
            self.check_stop()
            fit = self.fitted[j]
            unknown = np.flatnonzero(~self.known[:, j])
            if fit is not None and unknown.size:
                v = self.values[:, j]
                real = training_frames(v, self.known[:, j], pr.max_train_frames)
                extra = training_frames(out[:, j], chosen & ~self.known[:, j], pr.max_train_frames)
                frames = np.concatenate((real, extra))
                y = np.where(self.known[:, j], v, out[:, j]).astype(np.int8)
                w = np.concatenate((np.ones(real.size), np.full(extra.size, pr.pseudo_weight)))
                if np.unique(y[frames]).size == 2:
                    model = _fit(self.embedding, y, frames, w, pr.c, fit[1])
                    self.decision[unknown, j] = strided_decision(
                        model, self.embedding, self.clip_of_frame, self.counts, unknown, pr.step
                    )
                    self.models[j].train_frames = int(frames.size)
                    self.models[j].support_vectors = int(model.support_.size)
            self.step_done(r * n_labels + j + 1, f"self-training round {r}: label {name!r}")
