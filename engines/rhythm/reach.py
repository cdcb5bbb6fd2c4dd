"""Where a dance can go on the movement transition graph: reachability between groups.

Synthesis starts a dance in a group drawn from the start distribution ``pi (K,)`` and then draws
each next group from the current one's row of ``P (K, K)`` (zero = no transition). So:

* group ``j`` is *reachable from* group ``i`` when a chain of transitions (possibly none) leads
  from ``i`` to ``j`` (:func:`reachable`);
* a *start-only* group is one a dance can be in only by starting there (or in a group of its own
  strongly connected component): no group outside its component that a dance can be in leads to it
  (:func:`start_only_groups`). Once a dance leaves it, it never comes back;
* an *unreachable* group is one no dance is ever in: not a start group (``pi = 0``, possible with
  ``count_smoothing`` 0) and reachable from none (:func:`unreachable_groups`).

The learned graph has no dead end (every row keeps its likeliest transition, KPS03 Sec. 4.2), but
it need not be strongly connected: a group that starts an example and that no movement leads into
well enough (every likelihood into it at or below ``edge_threshold``) is start-only.

The graph has a few dozen nodes, so ``(K, K)`` boolean matrices are small.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from scipy.sparse.csgraph import connected_components

Bool = npt.NDArray[np.bool_]


def reachable(edges: Bool) -> Bool:
    """``(K, K)`` ``r[i, j]``: group ``j`` is reachable from group ``i`` in zero or more transitions
    of ``edges (K, K)`` (``edges[i, j]``: a transition ``i -> j``). Reflexive: ``r[i, i]`` is True."""
    k = edges.shape[0]
    r = np.asarray(edges, dtype=bool) | np.eye(k, dtype=bool)
    while True:  # squaring doubles the chain length covered: log2(K) rounds
        nxt = (r.astype(np.int64) @ r.astype(np.int64)) > 0
        if np.array_equal(nxt, r):
            return r
        r = nxt


def danced_groups(edges: Bool, start: npt.NDArray[np.float64]) -> Bool:
    """``(K,)`` the groups a dance can be in: a start group (``start > 0``) or reachable from one."""
    r = reachable(edges)
    return np.asarray((r & (np.asarray(start) > 0)[:, None]).any(axis=0), dtype=bool)


def unreachable_groups(edges: Bool, start: npt.NDArray[np.float64]) -> list[int]:
    """The groups no dance is ever in (module doc), ascending."""
    return [int(g) for g in np.flatnonzero(~danced_groups(edges, start))]


def start_only_groups(edges: Bool, start: npt.NDArray[np.float64]) -> list[int]:
    """The groups a dance is in only by starting there or in their own strongly connected component
    (module doc), ascending; none when the groups a dance can be in are strongly connected."""
    danced = np.flatnonzero(danced_groups(edges, start))
    sub = np.asarray(edges, dtype=bool)[np.ix_(danced, danced)]
    n, comp = connected_components(sub, directed=True, connection="strong")
    if n <= 1:
        return []
    r = reachable(sub)
    comes_from_outside = (r & (comp[:, None] != comp[None, :])).any(axis=0)
    return [int(g) for g in danced[~comes_from_outside]]


def lost_reach(before: Bool, after: Bool) -> Bool:
    """``(K, K)`` the pairs ``(i, j)`` with ``j`` reachable from ``i`` over the transitions ``before``
    and no longer over ``after`` (both ``(K, K)`` transition patterns)."""
    return np.asarray(reachable(before) & ~reachable(after), dtype=bool)


def describe(p: npt.NDArray[np.float64], start: npt.NDArray[np.float64]) -> str:
    """One line on a learned graph ``p (K, K)`` with start distribution ``start (K,)``: its groups and
    transitions, that it has no dead end (the build keeps every row's likeliest transition), and
    whether it is strongly connected, naming start-only and unreachable groups when not."""
    edges = np.asarray(p) > 0
    k = edges.shape[0]
    head = f"movement graph: {k} groups, {int(edges.sum())} transitions, no dead end"
    n, _ = connected_components(edges, directed=True, connection="strong")
    if n == 1:
        return head + ", strongly connected"
    parts = []
    only = start_only_groups(edges, start)
    never = unreachable_groups(edges, start)
    if only:
        parts.append(f"start-only groups {only} (no other group leads to them)")
    if never:
        parts.append(f"unreachable groups {never} (no dance is ever in them)")
    return head + ", NOT strongly connected: " + ("; ".join(parts) or f"{n} parts")
