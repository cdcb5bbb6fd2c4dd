"""Compiled (numba) versions of the per-frame loops a control request runs over whole clips.

Each does the arithmetic of its numpy counterpart joint by joint and frame by frame in one pass,
without numpy's temporaries:

* :func:`fast_fk` -- :meth:`motion.Motion.fk` (~1 ms instead of ~6 ms for a 17 s, 43-joint salsa clip
  at 120 fps). Each global rotation is the same quaternion product as
  :func:`motion.kinematics.global_rotations_soa` (the same bits); each position is its parent's
  plus the rotated local translation (numpy sums the rotated translations along the chain with
  one matrix product), so positions agree to rounding (~1e-15 relative).
* :func:`sample_into` -- :func:`motion.resample.sample_arrays_at` written into rows of output
  arrays (linear positions, slerp rotations; ~1 ms instead of ~6 ms for 2000 frames of 43
  joints). The same formulas; ``arccos`` is the C library's rather than numpy's (they differ in
  the last bit for some inputs), so rotations agree to ~1e-16.

Compiled with ``cache=True``: the first call in a fresh environment compiles (a few seconds),
later processes load the machine code from numba's cache (:mod:`motion.jitcache`; numba's import
and the load take a few hundred milliseconds once per process).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from .errors import MotionError
from .jitcache import compiled_ready, configure
from .motion import Motion
from .resample import checked_frames

configure()  # numba's cache outside the package, before numba is imported

from numba import njit  # noqa: E402

Array = npt.NDArray[np.float64]


@njit(cache=True, nogil=True)
def _fk_kernel(
    parents: np.ndarray,
    offsets: np.ndarray,
    slot: np.ndarray,
    root: np.ndarray,
    jt: np.ndarray,
    q: np.ndarray,
    pos: np.ndarray,
    grot: np.ndarray,
) -> None:  # pragma: no cover - compiled; tested through fast_fk
    """Fill ``pos (F, J, 3)`` and ``grot (F, J, 4)`` from local rotations ``q (F, J, 4)``: the
    root's translation is ``root (F, 3)``, joint ``j``'s is ``jt[:, slot[j]]`` when ``slot[j] >= 0``
    and ``offsets[j]`` otherwise."""
    n_frames, n_joints = q.shape[0], q.shape[1]
    for f in range(n_frames):
        for j in range(n_joints):
            bx, by, bz, bw = q[f, j, 0], q[f, j, 1], q[f, j, 2], q[f, j, 3]
            if j == 0:
                vx, vy, vz = root[f, 0], root[f, 1], root[f, 2]
            elif slot[j] >= 0:
                k = slot[j]
                vx, vy, vz = jt[f, k, 0], jt[f, k, 1], jt[f, k, 2]
            else:
                vx, vy, vz = offsets[j, 0], offsets[j, 1], offsets[j, 2]
            p = parents[j]
            if p < 0:
                grot[f, j, 0], grot[f, j, 1], grot[f, j, 2], grot[f, j, 3] = bx, by, bz, bw
                pos[f, j, 0], pos[f, j, 1], pos[f, j, 2] = vx, vy, vz
                continue
            x, y, z, w = grot[f, p, 0], grot[f, p, 1], grot[f, p, 2], grot[f, p, 3]
            grot[f, j, 0] = w * bx + x * bw + y * bz - z * by
            grot[f, j, 1] = w * by - x * bz + y * bw + z * bx
            grot[f, j, 2] = w * bz + x * by - y * bx + z * bw
            grot[f, j, 3] = w * bw - x * bx - y * by - z * bz
            cx = 2.0 * (y * vz - z * vy)
            cy = 2.0 * (z * vx - x * vz)
            cz = 2.0 * (x * vy - y * vx)
            pos[f, j, 0] = pos[f, p, 0] + (vx + w * cx + (y * cz - z * cy))
            pos[f, j, 1] = pos[f, p, 1] + (vy + w * cy + (z * cx - x * cz))
            pos[f, j, 2] = pos[f, p, 2] + (vz + w * cz + (x * cy - y * cx))


def _fk_numpy(
    parents: npt.NDArray[np.int64],
    offsets: Array,
    slot: npt.NDArray[np.int64],
    root: Array,
    jt: Array,
    q: Array,
    pos: Array,
    grot: Array,
) -> None:
    """:func:`_fk_kernel` in NumPy, joint by joint over all frames at once: each value is the same
    operations in the same order, so the same bits (its twin until ``segue warm`` compiled the
    kernel, :func:`motion.jitcache.compiled_ready`; a parent precedes its children, as in a BVH)."""
    for j in range(q.shape[1]):
        bx, by, bz, bw = q[:, j, 0], q[:, j, 1], q[:, j, 2], q[:, j, 3]
        if j == 0:
            vx, vy, vz = root[:, 0], root[:, 1], root[:, 2]
        elif slot[j] >= 0:
            k = int(slot[j])
            vx, vy, vz = jt[:, k, 0], jt[:, k, 1], jt[:, k, 2]
        else:
            vx, vy, vz = offsets[j, 0], offsets[j, 1], offsets[j, 2]
        p = int(parents[j])
        if p < 0:
            grot[:, j, 0], grot[:, j, 1], grot[:, j, 2], grot[:, j, 3] = bx, by, bz, bw
            pos[:, j, 0], pos[:, j, 1], pos[:, j, 2] = vx, vy, vz
            continue
        x, y, z, w = grot[:, p, 0], grot[:, p, 1], grot[:, p, 2], grot[:, p, 3]
        grot[:, j, 0] = w * bx + x * bw + y * bz - z * by
        grot[:, j, 1] = w * by - x * bz + y * bw + z * bx
        grot[:, j, 2] = w * bz + x * by - y * bx + z * bw
        grot[:, j, 3] = w * bw - x * bx - y * by - z * bz
        cx = 2.0 * (y * vz - z * vy)
        cy = 2.0 * (z * vx - x * vz)
        cz = 2.0 * (x * vy - y * vx)
        pos[:, j, 0] = pos[:, p, 0] + (vx + w * cx + (y * cz - z * cy))
        pos[:, j, 1] = pos[:, p, 1] + (vy + w * cy + (z * cx - x * cz))
        pos[:, j, 2] = pos[:, p, 2] + (vz + w * cz + (x * cy - y * cx))


def fast_fk(motion: Motion) -> tuple[Array, Array]:
    """:meth:`Motion.fk` of ``motion`` in one compiled pass: global ``positions (F, J, 3)`` in the
    motion's units and ``rotations (F, J, 4)`` (frame-major arrays; the same values up to rounding)."""
    sk = motion.skeleton
    n, j = motion.num_frames, sk.num_joints
    slot = np.full(j, -1, dtype=np.int64)
    slot[sk.translated_joints] = np.arange(sk.translated_joints.size)
    pos = np.empty((n, j, 3))
    grot = np.empty((n, j, 4))
    jt = motion.joint_translations if motion.joint_translations.shape[1] else np.zeros((n, 1, 3))
    (_fk_kernel if compiled_ready() else _fk_numpy)(
        np.asarray(sk.parents, dtype=np.int64),
        np.asarray(sk.offsets, dtype=np.float64),
        slot,
        np.ascontiguousarray(motion.root_positions, dtype=np.float64),
        np.ascontiguousarray(jt, dtype=np.float64),
        np.ascontiguousarray(motion.rotations, dtype=np.float64),  # one specialisation (C order)
        pos,
        grot,
    )
    return pos, grot


@njit(cache=True, nogil=True)
def _sample_kernel(
    root: np.ndarray,
    jt: np.ndarray,
    q: np.ndarray,
    frames: np.ndarray,
    rows: np.ndarray,
    out_root: np.ndarray,
    out_jt: np.ndarray,
    out_q: np.ndarray,
) -> None:  # pragma: no cover - compiled; tested through sample_into
    """``out_*[rows[k]]`` = the clip ``(root (F, 3), jt (F, K, 3), q (F, J, 4))`` at fractional
    frame ``frames[k]`` (linear positions, shorter-arc slerp, as :func:`motion.rotations.slerp`)."""
    n = q.shape[0]
    m = frames.size
    lo = np.empty(m, dtype=np.int64)
    hi = np.empty(m, dtype=np.int64)
    w = np.empty(m)
    for k in range(m):
        f = frames[k]
        lo[k] = min(int(np.floor(f)), max(n - 2, 0))
        hi[k] = min(lo[k] + 1, n - 1)
        w[k] = f - lo[k]
        r = rows[k]
        t = w[k]
        for c in range(3):
            out_root[r, c] = root[lo[k], c] * (1 - t) + root[hi[k], c] * t
        for j in range(jt.shape[1]):
            for c in range(3):
                out_jt[r, j, c] = jt[lo[k], j, c] * (1 - t) + jt[hi[k], j, c] * t
    # joint by joint: consecutive frames of one joint are near each other in a BVH clip's
    # (4, J, F) rotations, while one frame's joints are far apart
    for j in range(q.shape[1]):
        for k in range(m):
            i0, i1, t, r = lo[k], hi[k], w[k], rows[k]
            ax, ay, az, aw = q[i0, j, 0], q[i0, j, 1], q[i0, j, 2], q[i0, j, 3]
            bx, by, bz, bw = q[i1, j, 0], q[i1, j, 1], q[i1, j, 2], q[i1, j, 3]
            dot = ((ax * bx + ay * by) + az * bz) + aw * bw
            if dot < 0:
                bx, by, bz, bw = -bx, -by, -bz, -bw
            dot = abs(dot)
            theta = np.arccos(min(max(dot, -1.0), 1.0))
            sin_theta = np.sin(theta)
            if sin_theta < 1e-9:
                wa, wb = 1.0 - t, t
            else:
                wa = np.sin((1.0 - t) * theta) / sin_theta
                wb = np.sin(t * theta) / sin_theta
            ox, oy, oz, ow = wa * ax + wb * bx, wa * ay + wb * by, wa * az + wb * bz, wa * aw + wb * bw
            norm = np.sqrt(((ox * ox + oy * oy) + oz * oz) + ow * ow)
            out_q[r, j, 0], out_q[r, j, 1], out_q[r, j, 2], out_q[r, j, 3] = (
                ox / norm,
                oy / norm,
                oz / norm,
                ow / norm,
            )


def sample_into(
    motion: Motion,
    frames: Array,
    rows: npt.NDArray[np.intp],
    root: Array,
    rotations: Array,
    joint_translations: Array,
) -> None:
    """Write ``motion`` sampled at fractional frames ``frames (N,)`` in ``[0, F-1]`` into rows
    ``rows (N,)`` of ``root (M, 3)``, ``rotations (M, J, 4)`` and ``joint_translations (M, K, 3)``
    (C-contiguous float64; :func:`motion.resample.sample_arrays_at` for pieces of several clips
    written into one output)."""
    f = checked_frames(motion, frames)
    n = motion.num_frames
    idx = np.asarray(rows, dtype=np.int64)
    if idx.shape != f.shape:
        raise MotionError(f"{idx.size} rows for {f.size} frames")
    for out in (root, rotations, joint_translations):
        if not (out.flags.c_contiguous and out.dtype == np.float64):
            raise MotionError("output arrays must be C-contiguous float64")
    jt = motion.joint_translations if motion.joint_translations.shape[1] else np.zeros((n, 0, 3))
    _sample_kernel(motion.root_positions, jt, motion.rotations, f, idx, root, joint_translations, rotations)
