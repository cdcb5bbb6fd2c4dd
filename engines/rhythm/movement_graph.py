"""Groups of basic movements and the movement transition graph (Kim, Park & Shin 2003, Sec. 4).

* :func:`k_medoids` — K given: the paper's K-means with group centres restricted to members
  (Eq. 16-17), several random initial assignments, the best objective kept.
* :func:`subtractive_clustering` — K unknown: Chiu's potentials (Eq. 18-20).
* :func:`transition_graph` — ``P = w1 P_k + w2 P_b`` (Eq. 27): the kinematic likelihood from the
  end/start posture distances between groups (Eq. 21-22) and the behavioural likelihood from the
  transitions observed in the examples (Eq. 23-26).

Behavioural likelihood: the paper estimates ``P_b`` and ``pi`` with Baum-Welch. Here every basic
movement's group is known (the clustering assigns it), so the state sequence of each example is
observed and the Baum-Welch re-estimates (Eq. 25-26: expected transition counts over expected
visits) reduce, in one step and exactly, to the observed counts; additive smoothing
(``count_smoothing``) keeps unseen transitions possible. This is the observed-state special case.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from motion import MotionError

Array = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.intp]


def k_medoids(d: Array, k: int, rng: np.random.Generator, restarts: int = 8, max_iter: int = 100) -> IntArray:
    """``(M,)`` group of every item, from the ``(M, M)`` difference matrix ``d`` and ``k`` groups.

    Random initial assignment, then alternate: centre of each group = the member minimizing the
    sum of differences to the others (Eq. 17); every item joins its nearest centre. Restarts keep
    the lowest objective (Eq. 16). Groups are renumbered by first appearance.
    """
    m = d.shape[0]
    if not 1 <= k <= m:
        raise MotionError(f"cannot make {k} groups of {m} movements")
    best_cost, best = np.inf, np.zeros(m, dtype=np.intp)
    for _ in range(max(restarts, 1)):
        labels = rng.permutation(np.arange(m) % k)
        centres = np.zeros(k, dtype=np.intp)
        for _ in range(max_iter):
            for g in range(k):
                members = np.flatnonzero(labels == g)
                if members.size == 0:  # an emptied group takes the item farthest from its centre
                    far = int(np.argmax(d[np.arange(m), centres[labels]]))
                    labels[far] = g
                    members = np.array([far])
                centres[g] = members[np.argmin(d[np.ix_(members, members)].sum(axis=1))]
            new = np.argmin(d[:, centres], axis=1).astype(np.intp)
            new[centres] = np.arange(k)
            if np.array_equal(new, labels):
                break
            labels = new
        cost = float(d[np.arange(m), centres[labels]].sum())
        if cost < best_cost:
            best_cost, best = cost, labels.copy()
    return _renumber(best)


def subtractive_clustering(
    d: Array, radius: float, squash: float = 1.5, stop_ratio: float = 0.15
) -> IntArray:
    """``(M,)`` groups by subtractive clustering on differences ``d`` (Chiu 1994; Eq. 18-20).

    ``radius`` r: potentials ``P_i = sum_j exp(-d_ij / r^2)``; each chosen centre ``m`` lowers the
    others by ``P_m exp(-d_im / (s r^2))`` (``s = squash > 1``); centres are taken until the highest
    remaining potential falls below ``stop_ratio`` times the first centre's. Every item joins the
    centre of greatest influence (nearest).
    """
    if radius <= 0 or squash <= 1:
        raise MotionError("subtractive clustering needs radius > 0 and squash > 1")
    r2 = radius * radius
    pot = np.exp(-d / r2).sum(axis=1)
    first = float(pot.max())
    centres: list[int] = []
    while True:
        c = int(np.argmax(pot))
        if centres and pot[c] < stop_ratio * first:
            break
        centres.append(c)
        pot = pot - pot[c] * np.exp(-d[:, c] / (squash * r2))
        pot[centres] = -np.inf
        if len(centres) == d.shape[0]:
            break
    labels = np.argmin(d[:, centres], axis=1).astype(np.intp)
    labels[centres] = np.arange(len(centres))
    return _renumber(labels)


def _renumber(labels: IntArray) -> IntArray:
    _, first = np.unique(labels, return_index=True)
    order = labels[np.sort(first)]
    remap = np.empty(int(labels.max()) + 1, dtype=np.intp)
    remap[order] = np.arange(order.size)
    return np.asarray(remap[labels], dtype=np.intp)


def medoids(d: Array, labels: IntArray) -> IntArray:
    """``(K,)`` the member of each group with the least summed difference to the others."""
    k = int(labels.max()) + 1
    out = np.empty(k, dtype=np.intp)
    for g in range(k):
        members = np.flatnonzero(labels == g)
        out[g] = members[np.argmin(d[np.ix_(members, members)].sum(axis=1))]
    return out


@dataclass(frozen=True, slots=True)
class TransitionGraph:
    """The movement transition graph.

    Attributes
    ----------
    p: ``(K, K)`` transition probabilities (rows sum to 1; zero = no edge).
    start: ``(K,)`` start distribution pi.
    kinematic, behavioural: ``(K, K)`` the two likelihoods before mixing.
    group_distance: ``(K, K)`` Eq. 21.
    """

    p: Array
    start: Array
    kinematic: Array
    behavioural: Array
    group_distance: Array


def _row_normalize(a: Array) -> Array:
    s = a.sum(axis=1, keepdims=True)
    return np.asarray(np.where(s > 0, a / np.where(s > 0, s, 1.0), 1.0 / a.shape[1]))


def transition_graph(
    trans_d: Array,
    labels: IntArray,
    sequences: list[IntArray],
    *,
    kinematic_weight: float = 0.5,
    sigma: float | None = None,
    threshold: float = 0.02,
    smoothing: float = 0.5,
) -> TransitionGraph:
    """Build the graph from movement end->start differences ``trans_d (M, M)``, the group of each
    movement and the movement index sequences of the examples (consecutive movements of a clip).

    Edges with ``P <= threshold`` are dropped and rows renormalized; a node whose edges would all
    be dropped keeps its most likely one, so there are no dead ends.
    """
    k = int(labels.max()) + 1
    onehot = np.zeros((labels.size, k))
    onehot[np.arange(labels.size), labels] = 1.0
    counts = onehot.sum(axis=0)
    # Eq. 21: root mean square of member end/start differences
    dg = np.sqrt(np.maximum(onehot.T @ (trans_d**2) @ onehot, 0.0) / np.outer(counts, counts))
    scale = float(np.median(dg)) if sigma is None else sigma
    pk = _row_normalize(np.exp(-dg / max(scale, 1e-12)))
    obs = np.zeros((k, k))
    first = np.zeros(k)
    for seq in sequences:
        if seq.size == 0:
            continue
        g = labels[seq]
        first[g[0]] += 1
        np.add.at(obs, (g[:-1], g[1:]), 1.0)
    pb = _row_normalize(obs + smoothing)
    start = (first + smoothing) / (first + smoothing).sum()
    p = kinematic_weight * pk + (1.0 - kinematic_weight) * pb
    keep = p > threshold
    keep[np.arange(k), np.argmax(p, axis=1)] = True
    p = _row_normalize(np.where(keep, p, 0.0))
    return TransitionGraph(p=p, start=start, kinematic=pk, behavioural=pb, group_distance=dg)
