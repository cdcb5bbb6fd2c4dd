"""Closed-form rigid alignment of corresponding point sets.

* :func:`rigid_align_2d` — rotation about the vertical (Y) axis plus a translation on the floor,
  the alignment of Kovar & Gleicher and of Hsu et al. 2004; optionally weighted per point (e.g.
  per frame), batched over any leading axes.
* :func:`kabsch` — full 3-D rotation + translation (weighted Kabsch/Procrustes, no reflections);
  :func:`rotation_from_covariance` its rotation step, for callers that build the cross-covariances
  themselves (e.g. by matrix products over many windows at once).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from .errors import MotionError

Array = npt.NDArray[np.float64]


def _weights(points: Array, weights: Array | None) -> Array:
    n = points.shape[-2]
    if weights is None:
        return np.ones(points.shape[:-1])
    w = np.asarray(weights, dtype=np.float64)
    w = np.broadcast_to(w, points.shape[:-1]) if w.shape[-1:] == (n,) else w
    if w.shape != points.shape[:-1]:
        raise MotionError(f"weights {np.shape(weights)} do not match {n} points")
    if np.any(w < 0) or np.any(w.sum(axis=-1) <= 0):
        raise MotionError("weights must be non-negative with a positive sum")
    return w


def rigid_align_2d(source: Array, target: Array, weights: Array | None = None) -> tuple[Array, Array]:
    """Best rotation about +Y and floor translation taking ``source`` onto ``target``.

    Minimises ``sum_i w_i || R_y(theta) s_i + [tx, 0, tz] - t_i ||^2`` over the x and z coordinates
    (heights are left alone, as they are invariant under the transform).

    Parameters
    ----------
    source, target:
        ``(..., N, 3)`` corresponding points, Y up (any length unit).
    weights:
        ``(N,)`` or ``(..., N)`` non-negative weights (default: all 1).

    Returns
    -------
    theta:
        ``(...)`` rotation about +Y in radians (positive takes +Z towards +X).
    translation:
        ``(..., 2)`` floor translation ``[tx, tz]`` applied after the rotation.

    Examples
    --------
    >>> s = np.array([[0.0, 0, 1], [1, 0, 0], [0, 1, 0]])
    >>> th, t = rigid_align_2d(s, apply_rigid_2d(s, np.pi / 2, np.array([2.0, 3.0])))
    >>> round(float(th), 6), t.round(6).tolist()
    (1.570796, [2.0, 3.0])
    """
    s = np.asarray(source, dtype=np.float64)
    t = np.asarray(target, dtype=np.float64)
    if s.shape != t.shape or s.shape[-1] != 3 or s.ndim < 2:
        raise MotionError(f"source {s.shape} and target {t.shape} must both be (..., N, 3)")
    w = _weights(s, weights)
    wsum = w.sum(axis=-1)
    sx, sz, tx, tz = s[..., 0], s[..., 2], t[..., 0], t[..., 2]
    msx = (w * sx).sum(-1) / wsum
    msz = (w * sz).sum(-1) / wsum
    mtx = (w * tx).sum(-1) / wsum
    mtz = (w * tz).sum(-1) / wsum
    csx, csz = sx - msx[..., None], sz - msz[..., None]
    ctx, ctz = tx - mtx[..., None], tz - mtz[..., None]
    # R_y(theta): x' = x cos + z sin, z' = -x sin + z cos; maximise sum w t.(R s)
    c = (w * (csx * ctx + csz * ctz)).sum(-1)
    sn = (w * (csz * ctx - csx * ctz)).sum(-1)
    theta = np.arctan2(sn, c)
    cos, sin = np.cos(theta), np.sin(theta)
    trans = np.stack((mtx - (cos * msx + sin * msz), mtz - (-sin * msx + cos * msz)), axis=-1)
    return np.asarray(theta), trans


def apply_rigid_2d(points: Array, theta: Array | float, translation: Array) -> Array:
    """Rotate points ``(..., N, 3)`` by ``theta (...)`` about +Y, then translate by ``[tx, tz] (..., 2)``."""
    p = np.asarray(points, dtype=np.float64)
    th = np.asarray(theta, dtype=np.float64)[..., None]
    tr = np.asarray(translation, dtype=np.float64)
    cos, sin = np.cos(th), np.sin(th)
    out = p.copy()
    out[..., 0] = cos * p[..., 0] + sin * p[..., 2] + tr[..., 0:1]
    out[..., 2] = -sin * p[..., 0] + cos * p[..., 2] + tr[..., 1:2]
    return out


def kabsch(source: Array, target: Array, weights: Array | None = None) -> tuple[Array, Array]:
    """Best proper rotation and translation taking ``source`` onto ``target`` (weighted, 3-D).

    Parameters
    ----------
    source, target:
        ``(..., N, 3)`` corresponding points.
    weights:
        ``(N,)`` or ``(..., N)`` non-negative weights.

    Returns
    -------
    rotation:
        ``(..., 3, 3)`` rotation matrices (determinant +1).
    translation:
        ``(..., 3)`` such that ``target ~ source @ rotation.T + translation``.
    """
    s = np.asarray(source, dtype=np.float64)
    t = np.asarray(target, dtype=np.float64)
    if s.shape != t.shape or s.shape[-1] != 3 or s.ndim < 2:
        raise MotionError(f"source {s.shape} and target {t.shape} must both be (..., N, 3)")
    w = _weights(s, weights)[..., None]
    wsum = w.sum(axis=-2)
    ms = (w * s).sum(-2) / wsum
    mt = (w * t).sum(-2) / wsum
    h = np.einsum("...ni,...nj->...ij", w * (s - ms[..., None, :]), t - mt[..., None, :])
    r, _ = rotation_from_covariance(h)
    trans = mt - np.einsum("...ij,...j->...i", r, ms)
    return r, trans


def rotation_from_covariance(h: Array) -> tuple[Array, Array]:
    """The Kabsch step: from centred cross-covariances ``h = sum_n w_n s_n t_n^T`` ``(..., 3, 3)``
    (source points ``s``, target points ``t``), the proper rotations ``(..., 3, 3)`` maximising
    ``trace(R h)`` (so ``R s`` best matches ``t``) and that maximum ``(...,)``: the sum of the
    singular values, the smallest one's sign flipped where a reflection would fit better. The
    weighted residual is then ``sum w |s|^2 + sum w |t|^2 - 2 maximum`` (centred points)."""
    hh = np.asarray(h, dtype=np.float64)
    if hh.shape[-2:] != (3, 3):
        raise MotionError(f"cross-covariances must be (..., 3, 3), got {hh.shape}")
    u, sv, vt = np.linalg.svd(hh)
    d = np.sign(np.linalg.det(vt.swapaxes(-1, -2) @ u.swapaxes(-1, -2)))
    d = np.where(d == 0, 1.0, d)
    fix = np.ones((*d.shape, 3))
    fix[..., 2] = d
    r = vt.swapaxes(-1, -2) @ (fix[..., :, None] * u.swapaxes(-1, -2))
    return r, sv[..., 0] + sv[..., 1] + d * sv[..., 2]
