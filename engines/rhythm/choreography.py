"""Editing the movement transition graph by choreographic rules (Kim, Park & Shin 2003, Sec. 4.3).

The paper lets a choreographer connect groups whose transitions the examples left out, adjust the
likelihoods of transitions, and avoid dead ends. Here:

* :func:`movement_graph` describes a built database's graph (:class:`schemas.movement_graph.MovementGraph`):
  each group with its representative movement (the medoid) as a span of an example clip and a
  thumbnail pose, each transition with the probability synthesis draws with and its kinematic and
  behavioural likelihoods.
* :func:`resolve_edits` turns edits that name groups by id or by a clip span into group ids.
* :func:`apply_edits` applies them in order to the transition matrix ``P (K, K)`` (the learned
  ``rhythm.p``: rows sum to 1, zero = no edge) and checks the rules on the result:

  The rules judge what the edits *change*, so a graph that is not strongly connected as learned
  (:mod:`engines.rhythm.reach`: a start-only group) can be edited too:

  - **no new dead end**: every group that had an outgoing transition keeps one. Synthesis draws
    each next group from the row of the current one; an empty row has nothing to draw from.
  - **no group made unreachable**: every group stays reachable from every group it was reachable
    from before the edits (in any number of transitions). Once a dance leaves a part of the graph
    it cannot get back to, the groups there are lost for the rest of the dance, so an edit may not
    create such a part; a part the examples left that way (a start-only group) may stay so.
  - weights positive and finite (the schema refuses others).

  Each violation raises :class:`GraphEditError` naming the offending edit.
* :func:`edited_arrays` is the derived database: the parent's arrays with ``rhythm.p`` replaced
  (and the learned matrix kept as ``rhythm.learned_p``), so synthesis, live sessions and crowds all
  walk the edited graph, with nothing else changed.

The graph has a few dozen nodes (one per group of basic movements), so ``(K, K)`` matrices are small.
"""

from __future__ import annotations

import json
from dataclasses import replace
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.sparse.csgraph import connected_components

from motion import Motion
from motion.ground import body_root
from motion.serialize import skeleton_from_arrays
from schemas.movement_graph import (
    ClipSpan,
    DerivedFrom,
    GraphEdit,
    GraphGroup,
    GraphTransition,
    MovementGraph,
    RepresentativeSpan,
    ResolvedEdit,
)

from ..base import EngineError
from .reach import lost_reach, start_only_groups, unreachable_groups
from .synth import draw_probabilities

Array = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]
Arrays = dict[str, npt.NDArray[Any]]


class GraphEditError(EngineError):
    """An edit the graph refuses: ``index`` is the offending edit's place in the list (None when
    the learned graph itself breaks a rule), ``details`` a JSON-ready explanation."""

    def __init__(self, message: str, index: int | None = None, details: dict[str, Any] | None = None):
        super().__init__(message)
        self.index = index
        self.details = {"edit": index, **(details or {})}


def _meta(arrays: Any) -> dict[str, Any]:
    if "rhythm.meta" not in arrays:
        raise EngineError("not a rhythm database: it has no movement transition graph")
    return dict(json.loads(str(arrays["rhythm.meta"])))


# -- naming groups ------------------------------------------------------------------------------
def group_of_span(span: ClipSpan, arrays: Any) -> int:
    """The group of the basic movement (of the clip as danced, not mirrored) that overlaps ``span``
    the most (an instant: the movement it falls in; on a beat between two, the later). Raises
    :class:`EngineError` naming the clip or the span when there is none."""
    meta = _meta(arrays)
    names: list[str] = meta["examples"]
    mirrored: list[bool] = meta.get("mirrored", [False] * len(names))
    fps = float(meta["fps"])
    try:
        ci = next(i for i, n in enumerate(names) if n == span.clip and not mirrored[i])
    except StopIteration:
        clips = ", ".join(dict.fromkeys(names))
        raise EngineError(f"no clip {span.clip!r} among the database's examples ({clips})") from None
    lo, hi = span.frames if span.frames is not None else (span.seconds or (0.0, 0.0))
    scale = 1.0 if span.frames is not None else fps
    a, b = float(lo) * scale, float(hi) * scale
    if b <= a:
        b = a + 1e-6  # an instant: the movement it falls in (a shared boundary frame goes to the later)
    src_clip = np.asarray(arrays["rhythm.src_clip"], dtype=np.intp)
    src = np.asarray(arrays["rhythm.src_frames"], dtype=np.float64)
    members = np.flatnonzero(src_clip == ci)
    starts, ends = src[members, 0], src[members, -1]
    overlap = np.minimum(ends, b) - np.maximum(starts, a)
    unit = "frames" if span.frames is not None else "seconds"
    if members.size == 0 or overlap.max() <= 0:
        spans = ", ".join(f"{s / scale:.6g}-{e / scale:.6g}" for s, e in zip(starts, ends, strict=True))
        raise EngineError(
            f"clip {span.clip!r} {unit} {lo}-{hi} fall in none of its basic movements "
            f"({unit}: {spans or 'none: the clip gave no regular movement'})"
        )
    labels = np.asarray(arrays["rhythm.labels"], dtype=np.intp)
    return int(labels[members[int(np.argmax(overlap))]])


def resolve_edits(edits: list[GraphEdit], arrays: Any) -> list[ResolvedEdit]:
    """Every edit with its groups as ids (``connect``'s weight defaulted to 1). Raises
    :class:`GraphEditError` naming the edit whose group id or clip span names no group."""
    k = int(np.asarray(arrays["rhythm.p"]).shape[0])
    out: list[ResolvedEdit] = []
    for i, e in enumerate(edits):
        ends: list[int] = []
        for role, ref in (("source", e.source), ("target", e.target)):
            if isinstance(ref, ClipSpan):
                try:
                    ends.append(group_of_span(ref, arrays))
                except EngineError as exc:
                    raise GraphEditError(
                        f"edit {i} ({e.op}): {role}: {exc}", i, {"field": role, "problem": "bad_span"}
                    ) from None
            elif not 0 <= ref < k:
                raise GraphEditError(
                    f"edit {i} ({e.op}): {role}: no group {ref} (groups are 0-{k - 1})",
                    i,
                    {"field": role, "problem": "unknown_group"},
                )
            else:
                ends.append(int(ref))
        weight = 1.0 if e.op == "connect" and e.weight is None else e.weight
        out.append(ResolvedEdit(op=e.op, source=ends[0], target=ends[1], weight=weight))
    return out


# -- applying and checking ----------------------------------------------------------------------
def _describe(e: ResolvedEdit, i: int) -> str:
    w = f" x{e.weight:g}" if e.weight is not None and e.op != "connect" else ""
    return f"edit {i} ({e.op} {e.source} -> {e.target}{w})"


def apply_edits(p: Array, edits: list[ResolvedEdit]) -> Array:
    """The transition matrix ``(K, K)`` after ``edits`` (in order; edited rows normalized at the end),
    checked against the rules of the module docstring. Raises :class:`GraphEditError`."""
    lik = np.array(p, dtype=np.float64, copy=True)
    emptied: dict[int, int] = {}  # group -> the edit that cut its last transition
    for i, e in enumerate(edits):
        a, b = e.source, e.target
        has = lik[a, b] > 0
        if e.op == "cut":
            if not has:
                raise GraphEditError(
                    f"{_describe(e, i)}: there is no transition {a} -> {b} to cut",
                    i,
                    {"problem": "no_transition"},
                )
            lik[a, b] = 0.0
            if not (lik[a] > 0).any():
                emptied[a] = i
        elif e.op == "weight":
            if not has:
                raise GraphEditError(
                    f"{_describe(e, i)}: there is no transition {a} -> {b} to weight (connect it first)",
                    i,
                    {"problem": "no_transition"},
                )
            lik[a, b] *= float(e.weight or 1.0)
            if lik[a, b] < 1e-250:
                raise GraphEditError(
                    f"{_describe(e, i)}: the weights underflow (cut the transition instead)",
                    i,
                    {"problem": "underflow"},
                )
        else:
            if has:
                raise GraphEditError(
                    f"{_describe(e, i)}: the transition {a} -> {b} exists already (weight it instead)",
                    i,
                    {"problem": "exists"},
                )
            row = lik[a][lik[a] > 0]
            lik[a, b] = float(e.weight or 1.0) * (float(row.mean()) if row.size else 1.0)
            emptied.pop(a, None)
        if not np.isfinite(lik[a]).all() or lik[a].max() > 1e300:
            raise GraphEditError(f"{_describe(e, i)}: the weights overflow", i, {"problem": "overflow"})
    _check_rules(np.asarray(p), lik, edits, emptied)
    rows = sorted({e.source for e in edits})  # rows no edit touched stay exactly as they were
    lik[rows] = lik[rows] / lik[rows].sum(axis=1, keepdims=True)
    return lik


def _check_rules(before: Array, lik: Array, edits: list[ResolvedEdit], emptied: dict[int, int]) -> None:
    """The rules of the module docstring, judged on what ``edits`` changed from ``before (K, K)`` to
    ``lik (K, K)``: a group that had a transition out keeps one, and every group stays reachable
    from every group it was reachable from (:mod:`engines.rhythm.reach`)."""
    was, now = before > 0, lik > 0
    dead = np.flatnonzero(was.any(axis=1) & ~now.any(axis=1))
    if dead.size:
        g = int(dead[0])
        i = emptied.get(g)
        where = f"{_describe(edits[i], i)} cuts the last transition out of group {g}" if i is not None else ""
        raise GraphEditError(
            f"{where or f'group {g} has no outgoing transition'}: a dead end (every group needs "
            "a transition out; connect it to another group)",
            i,
            {"problem": "dead_end", "groups": [int(x) for x in dead]},
        )
    lost = lost_reach(was, now)
    if not lost.any():
        return
    targets = [int(x) for x in np.flatnonzero(lost.any(axis=0))]
    sources = [int(x) for x in np.flatnonzero(lost.any(axis=1))]
    i = _culprit(was, now, lost, edits)
    lead = f"{_describe(edits[i], i)} makes" if i is not None else "the edits make"
    raise GraphEditError(
        f"{lead} groups {_short(targets)} unreachable from groups {_short(sources)}: a dance in "
        f"those never reaches groups {_short(targets)} again, as it could before (edits must keep "
        "every group as reachable as it was; connect the groups another way, or cut less)",
        i,
        {"problem": "unreachable", "unreachable_groups": targets, "from_groups": sources},
    )


def _culprit(was: BoolArray, now: BoolArray, lost: BoolArray, edits: list[ResolvedEdit]) -> int | None:
    """The last cut whose transition, given back alone, gives back some of the ``lost`` reach."""
    for i in range(len(edits) - 1, -1, -1):
        e = edits[i]
        if e.op != "cut" or now[e.source, e.target]:
            continue
        back = now.copy()
        back[e.source, e.target] = True
        if (lost & ~lost_reach(was, back)).any():
            return i
    return None


def _short(groups: list[int], most: int = 12) -> str:
    return str(groups) if len(groups) <= most else f"{groups[:most]} (+{len(groups) - most} more)"


def edited_arrays(arrays: Any, edits: list[ResolvedEdit]) -> Arrays:
    """The arrays of the database derived by ``edits``: every array of ``arrays`` as it is, but
    ``rhythm.p`` edited (:func:`apply_edits`) and ``rhythm.learned_p`` holding the graph learned
    from the examples (kept from the first derivation on)."""
    _meta(arrays)
    out: Arrays = {k: np.asarray(arrays[k]) for k in arrays}
    p = np.asarray(arrays["rhythm.p"], dtype=np.float64)
    out["rhythm.p"] = apply_edits(p, edits)
    out.setdefault("rhythm.learned_p", p)
    return out


# -- describing ---------------------------------------------------------------------------------
def _pose(arrays: Any, movement: int, frame: int, clip_index: int, fps: float) -> list[list[float]]:
    """``(J, 3)`` joint positions of a movement at one of its frames, the body root moved above the
    origin (rounded to millimetres)."""
    base = skeleton_from_arrays(arrays, "library.skeleton.")
    offsets = np.asarray(arrays["library.offsets"])
    ends = np.asarray(arrays["library.end_site_offsets"])
    sk = replace(base, offsets=offsets[clip_index], end_site_offsets=ends[clip_index])
    jt = np.asarray(arrays["rhythm.jt"])
    m = Motion(
        sk,
        np.asarray(arrays["rhythm.root"][movement, frame : frame + 1], dtype=np.float64),
        np.asarray(arrays["rhythm.rot"][movement, frame : frame + 1], dtype=np.float64),
        fps,
        np.asarray(jt[movement, frame : frame + 1], dtype=np.float64),
        "m",
        "thumbnail",
    )
    pos = m.global_positions()[0]
    r = body_root(sk)
    pos[:, [0, 2]] -= pos[r, [0, 2]]
    return np.round(pos, 3).tolist()  # type: ignore[no-any-return]


def movement_graph(
    arrays: Any,
    database: str,
    kinematic_weight: float | None = None,
    derived_from: DerivedFrom | None = None,
) -> MovementGraph:
    """The graph of a built rhythm database (module doc). ``arrays``: its ``data.npz`` (a dict or an
    ``NpzFile``); ``kinematic_weight``: w1 from its spec, when known."""
    meta = _meta(arrays)
    fps = float(meta["fps"])
    names: list[str] = meta["examples"]
    mirrored: list[bool] = meta.get("mirrored", [False] * len(names))
    lib_names = [str(n) for n in arrays["library.names"]]
    p = np.asarray(arrays["rhythm.p"], dtype=np.float64)
    learned = np.asarray(arrays.get("rhythm.learned_p", p)) > 0
    pk = np.asarray(arrays["rhythm.kinematic"], dtype=np.float64)
    pb = np.asarray(arrays["rhythm.behavioural"], dtype=np.float64)
    start = np.asarray(arrays["rhythm.start"], dtype=np.float64)
    labels = np.asarray(arrays["rhythm.labels"], dtype=np.intp)
    centre = np.asarray(arrays["rhythm.medoids"], dtype=np.intp)
    src_clip = np.asarray(arrays["rhythm.src_clip"], dtype=np.intp)
    src = np.asarray(arrays["rhythm.src_frames"], dtype=np.float64)
    sizes = np.bincount(labels, minlength=p.shape[0])
    # what synthesis really draws with: the graph times each group's beat-clarity preference (at
    # a tempo that allows every movement: faster music avoids those too fast for it, synth.too_fast)
    clarity = np.asarray(arrays["rhythm.clarity"]) if "rhythm.clarity" in arrays else np.ones(labels.size)
    draw = draw_probabilities(p, clarity, labels)
    start_draw = draw_probabilities(start, clarity, labels)[0]
    n = src.shape[1]
    groups = []
    for g in range(p.shape[0]):
        m = int(centre[g])
        ci = int(src_clip[m])
        s, e = float(src[m, 0]), float(src[m, -1])
        mid = n // 2
        groups.append(
            GraphGroup(
                id=g,
                size=int(sizes[g]),
                start_probability=round(float(start_draw[g]), 6),
                representative=RepresentativeSpan(
                    clip=names[ci],
                    mirrored=bool(mirrored[ci]),
                    start_frame=int(round(s)),
                    end_frame=int(round(e)),
                    start_s=round(s / fps, 4),
                    end_s=round(e / fps, 4),
                ),
                pose=_pose(arrays, m, mid, lib_names.index(names[ci]), fps),
                pose_frame=int(round(float(src[m, mid]))),
            )
        )
    a, b = np.nonzero(p > 0)
    transitions = [
        GraphTransition(
            source=int(i),
            target=int(j),
            probability=round(float(draw[i, j]), 6),
            kinematic=round(float(pk[i, j]), 6),
            behavioural=round(float(pb[i, j]), 6),
            learned=bool(learned[i, j]),
        )
        for i, j in zip(a, b, strict=True)
    ]
    sk = skeleton_from_arrays(arrays, "library.skeleton.")
    n_comp, _ = connected_components(p > 0, directed=True, connection="strong")
    return MovementGraph(
        database=database,
        fps=fps,
        beats_per_movement=int(meta["beats_per_movement"]),
        kinematic_weight=kinematic_weight,
        joints=list(sk.names),
        parents=[int(x) for x in sk.parents],
        groups=groups,
        transitions=transitions,
        strongly_connected=n_comp == 1,
        start_only_groups=start_only_groups(p > 0, start),
        unreachable_groups=unreachable_groups(p > 0, start),
        derived_from=derived_from,
    )
