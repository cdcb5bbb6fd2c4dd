"""Blend weights of a group's movements from the requested speed and turning angle.

Each basic movement is parameterized by the arc fitted to its root path (speed m/s, turning angle
radians; :func:`engines.rhythm.movements.arc_parameters`). For a target ``(speed, turn)`` the
weights of a group's members come from cardinal basis functions (Sloan, Rose & Cohen 2001, as
used by Park et al. 2002): per member ``i``, a linear polynomial plus cubic radial basis functions
``phi(r) = r^3`` fitted so that ``w_i(x_j) = delta_ij`` — the weights reproduce each example at its
own parameters and vary smoothly in between. Negative weights are clipped and the rest
renormalized (blending quaternions with negative weights can flip joints); only the
``max_members`` largest weights are kept so the per-frame blend stays a few array operations.
Parameters are scaled by their spread over the database (speed by its standard deviation, turn
likewise) so the two axes are commensurate.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

Array = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.intp]


@dataclass(frozen=True, slots=True)
class GroupBlender:
    """Cardinal basis functions of every group, padded to the largest group.

    members: ``(K, G)`` movement index of each member (-1 padding); counts ``(K,)``;
    x: ``(K, G, 2)`` scaled parameters; lin: ``(K, 3, G)`` linear coefficients;
    rbf: ``(K, G, G)`` radial coefficients (row = basis centre, column = member); scale ``(2,)``.
    """

    members: IntArray
    counts: IntArray
    x: Array
    lin: Array
    rbf: Array
    scale: Array


def _phi(r: Array) -> Array:
    return np.asarray(r**3)


def fit_blender(params: Array, labels: IntArray) -> GroupBlender:
    """Fit the cardinal basis functions of each group from movement ``params (M, 2)``."""
    k = int(labels.max()) + 1
    scale = np.maximum(params.std(axis=0), np.array([0.05, np.radians(10.0)]))
    xs = params / scale
    groups = [np.flatnonzero(labels == g) for g in range(k)]
    gmax = max(g.size for g in groups)
    members = np.full((k, gmax), -1, dtype=np.intp)
    x = np.zeros((k, gmax, 2))
    lin = np.zeros((k, 3, gmax))
    rbf = np.zeros((k, gmax, gmax))
    for g, idx in enumerate(groups):
        n = idx.size
        members[g, :n] = idx
        xg = xs[idx]
        x[g, :n] = xg
        basis = np.concatenate((np.ones((n, 1)), xg), axis=1)
        # a linear part only where the points span it (3 points not on a line)
        cols = 3 if n >= 3 and np.linalg.matrix_rank(basis) == 3 else 1
        a, *_ = np.linalg.lstsq(basis[:, :cols], np.eye(n), rcond=None)  # (cols, n)
        resid = np.eye(n) - basis[:, :cols] @ a
        phi = _phi(np.linalg.norm(xg[:, None] - xg[None], axis=-1))
        r, *_ = np.linalg.lstsq(phi + 1e-9 * np.eye(n), resid, rcond=None)
        lin[g, :cols, :n] = a
        rbf[g, :n, :n] = r
    return GroupBlender(members, np.array([g.size for g in groups], dtype=np.intp), x, lin, rbf, scale)


def blend_weights(
    blender: GroupBlender, groups: IntArray, target: Array, max_members: int = 4
) -> tuple[IntArray, Array]:
    """Members ``(C, g)`` and weights ``(C, g)`` (non-negative, summing to 1) for characters in
    ``groups (C,)`` asking for parameters ``target (C, 2)`` (speed m/s, turn radians);
    ``g = min(max_members, largest group)``; padding has weight 0 and a valid member index."""
    xt = target / blender.scale
    xg = blender.x[groups]  # (C, G, 2)
    valid = blender.members[groups] >= 0
    basis = np.concatenate((np.ones((groups.size, 1)), xt), axis=1)  # (C, 3)
    w = np.einsum("cl,clg->cg", basis, blender.lin[groups])
    phi = _phi(np.linalg.norm(xg - xt[:, None], axis=-1)) * valid
    w += np.einsum("ch,chg->cg", phi, blender.rbf[groups])
    w = np.where(valid, np.maximum(w, 0.0), 0.0)
    total = w.sum(axis=1, keepdims=True)
    nearest = np.argmin(np.where(valid, np.linalg.norm(xg - xt[:, None], axis=-1), np.inf), axis=1)
    fallback = np.zeros_like(w)
    fallback[np.arange(groups.size), nearest] = 1.0
    w = np.where(total > 1e-9, w / np.where(total > 1e-9, total, 1.0), fallback)
    g = min(max_members, w.shape[1])
    top = np.argsort(-w, axis=1)[:, :g]
    wt = np.take_along_axis(w, top, axis=1)
    wt /= wt.sum(axis=1, keepdims=True)
    mem = np.take_along_axis(blender.members[groups], top, axis=1)
    mem = np.where(mem >= 0, mem, blender.members[groups, :1])
    return mem, wt


def one_hot(blender: GroupBlender, groups: IntArray, rng: np.random.Generator) -> tuple[IntArray, Array]:
    """A random member of each character's group with weight 1 (``(C, 1)`` members and weights):
    the blend at that member's own parameters (cardinal functions reproduce examples exactly)."""
    pick = np.floor(rng.random(groups.size) * blender.counts[groups]).astype(np.intp)
    return blender.members[groups, pick][:, None], np.ones((groups.size, 1))
