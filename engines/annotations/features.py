"""Per-frame embeddings of the annotation engine (Arikan, Forsyth & O'Brien 2003).

Two embeddings of every database frame, both in that frame's torso (ground) frame
(:func:`motion.ground.ground_frames`: origin on the floor under the hips, +Z along the heading,
+X to the body's left, Y up), so they do not depend on where the body stands or faces:

* :func:`window_embedding` (Sec. 3.1, the SVM input): the positions of a few joints over a
  one-second window centred on the frame, sampled at ``samples`` instants, ``(F, S*K*3)`` metres.
  The paper uses every joint at every frame of the window; a subsample keeps the SVM quick and
  loses little (neighbouring frames are nearly collinear). A coarser, longer context window
  (:func:`embedding_offsets`) adds what the body did before and after: the straight stretch of a
  turning walk and the raise of a raise-up look like plain walking and the raise of a wave
  within one second, not within four.
* :func:`continuity_features` (Sec. 3.2, the input of the PCA giving ``F(f)``): positions,
  velocities and accelerations of every body joint, each group divided by its RMS over the clip
  set so that the three carry comparable weight; ``(F, 9*J)``.
"""

from __future__ import annotations

import re
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from motion import Motion
from motion.ground import body_joints, ground_frames, to_ground_frame
from motion.skeleton import Skeleton

from ..base import EngineError

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.intp]

_SVM_JOINTS = re.compile(
    r"head|hand|wrist|forearm|lowerarm|elbow|foot|ankle|shin|lowerleg|knee|chest|spine2?$",
    re.IGNORECASE,
)


def svm_joint_indices(skeleton: Skeleton, names: Sequence[str] | None = None) -> IntArray:
    """Joints of the SVM window embedding: ``names`` (errors name unknown joints), else the head,
    hands, forearms, feet, shins and chest found by name, else every body joint."""
    if names is not None:
        missing = [n for n in names if n not in skeleton.names]
        if missing:
            raise EngineError(
                f"svm_joints: no joint named {', '.join(map(repr, missing))}; "
                f"joints: {', '.join(skeleton.names)}"
            )
        return np.array([skeleton.index(n) for n in names], dtype=np.intp)
    body = body_joints(skeleton)
    picked = [int(j) for j in body if _SVM_JOINTS.search(skeleton.names[j])]
    if len(picked) < 3:
        return body
    return np.array(picked, dtype=np.intp)


def window_offsets(fps: float, window_s: float, samples: int) -> IntArray:
    """``(S,)`` frame offsets of the window samples, symmetric about 0."""
    half = 0.5 * window_s * fps
    return np.unique(np.round(np.linspace(-half, half, samples)).astype(np.intp))


def embedding_offsets(
    fps: float, window_s: float, samples: int, context_s: float = 0.0, context_samples: int = 0
) -> IntArray:
    """``(S,)`` sorted frame offsets of the SVM embedding: the fine window
    (:func:`window_offsets`) and, when ``context_s > 0`` and ``context_samples > 0``, a coarse
    context window of ``context_samples`` instants over ``context_s`` seconds (shared offsets
    counted once)."""
    fine = window_offsets(fps, window_s, samples)
    if context_s <= 0 or context_samples <= 0:
        return fine
    return np.unique(np.concatenate((fine, window_offsets(fps, context_s, context_samples))))


def window_embedding(
    positions: FloatArray, origin_xz: FloatArray, heading: FloatArray, joints: IntArray, offsets: IntArray
) -> FloatArray:
    """``(F, S*K*3)`` metres: joints ``(K,)`` at frames ``f + offsets`` (clamped to the clip) in
    frame ``f``'s ground frame.

    Parameters
    ----------
    positions: ``(F, J, 3)`` metres, Y up, one clip.
    origin_xz, heading: ``(F, 2)`` metres and ``(F,)`` radians, the clip's ground frames.
    """
    n = positions.shape[0]
    idx = np.clip(np.arange(n)[:, None] + offsets[None, :], 0, n - 1)  # (F, S)
    pts = positions[idx][:, :, joints]  # (F, S, K, 3)
    local = to_ground_frame(pts.reshape(n, -1, 3), origin_xz, heading)
    return np.asarray(local.reshape(n, -1))


def _derivative(x: FloatArray, fps: float) -> FloatArray:
    if x.shape[0] < 2:
        return np.zeros_like(x)
    return np.asarray(np.gradient(x, 1.0 / fps, axis=0))


def continuity_raw(
    positions: FloatArray, origin_xz: FloatArray, heading: FloatArray, joints: IntArray, fps: float
) -> FloatArray:
    """``(F, 3, K*3)`` one clip's body-joint positions (m), velocities (m/s) and accelerations
    (m/s^2), world derivatives rotated into each frame's ground frame."""
    n = positions.shape[0]
    p = positions[:, joints]
    v = _derivative(p, fps)
    a = _derivative(v, fps)
    zero = np.zeros_like(origin_xz)
    local_p = to_ground_frame(p, origin_xz, heading)
    local_v = to_ground_frame(v, zero, heading)
    local_a = to_ground_frame(a, zero, heading)
    return np.stack((local_p.reshape(n, -1), local_v.reshape(n, -1), local_a.reshape(n, -1)), axis=1)


def clip_frames(motion: Motion) -> tuple[FloatArray, FloatArray, FloatArray]:
    """A clip's global positions ``(F, J, 3)`` metres and ground frames ``(F, 2)``, ``(F,)`` rad."""
    pos = motion.global_positions() * motion.metres_per_unit
    xz, yaw = ground_frames(motion, pos)
    return pos, np.asarray(xz), np.asarray(yaw)
