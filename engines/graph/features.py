"""Per-frame transition features: the cost of a cut is a squared Euclidean distance.

Arikan & Forsyth (2002), Appendix A, compare two frames by the differences of their joint
positions and velocities in the torso frame and of the torso's own velocity and acceleration,
each term normalised by the largest change between consecutive frames of the database and
weighted per joint (feet more than hands). This module folds all of that into one row per frame,

    C(a, b) = || x_a - x_b ||^2 ,   x = [ p~, v~, T~, A~, R~ ]  (float32, one row per frame)

where, for the frame's body joints ``k`` (the body root and its descendants, so a static
``joint_Root`` above the hips is left out) with weights ``w_k``:

* ``p~ = sqrt(lam_P / m_P) * sqrt(w_k) * p_k``: joint positions (m) in the frame's torso frame
  (``motion.features.torso_features``: origin on the floor under the body root, +Z along the
  heading, Y up), ``lam_P = 1``;
* ``v~ = sqrt(lam_V / m_V) * sqrt(w_k) * v_k``: joint velocities (m/s; world velocities
  expressed in the torso frame), ``lam_V = velocity_weight``;
* ``T~ = sqrt(1 / m_T) * T``: the body root's velocity (m/s, torso frame, 3 components);
* ``A~ = sqrt(lam_V / m_A) * A``: its acceleration (m/s^2, torso frame);
* ``R~ = sqrt(1 / m_R) * R``: the turning rate (rad/s about +Y);

all times ``sqrt(k)``, ``k`` below.

So ``C(a, b) = k * sum_g lam_g * d_g(a, b) / m_g`` with ``d_g`` the (joint-weighted) squared
difference of group ``g`` and ``m_g`` the *database maximum* of ``d_g`` between consecutive frames
of a clip (every clip, every frame pair ``(i, i + 1)``), as in the paper: each group's largest frame
step weighs the same. One global factor ``k`` then makes the database's *average* frame step cost
exactly 1 (``k = 1 / mean_i sum_g lam_g d_g(i, i + 1) / m_g``), so ``tau`` reads "as noticeable as
``tau`` frames of typical motion" (``GraphDatabaseSpec.tau``). Without ``k`` the average step
would cost a different amount on every database (0.36 on Bandai-Namco locomotion, whose median
step costs 0.57 once scaled). The rows are also centred (distances do not change).

Relation to Appendix A. Equation (2) stacks the joint-position differences with the differences of
the torso's speed ``|T|`` and turning ``|R|``; equation (5) is
``trace(D M O^-1 D^T + D' L^-1 D'^T)``: a weighted sum of squared differences, positions (and torso
velocity) normalised by ``O``, their derivatives by ``L``, both maxima of consecutive-frame
differences (equations 3, 4), joints weighted by the diagonal ``M``. Differences from the paper,
chosen to keep the cost a plain distance (so it can be computed by BLAS, blockwise):

* ``O`` and ``L`` are per group (positions, velocities, root velocity, acceleration, turning)
  rather than per joint: a per-joint maximum makes joints that hardly move (the pelvis height in
  the torso frame) dominate the cost.
* The torso velocity and acceleration are compared as vectors in the torso frame (forward, sideways,
  vertical), not as magnitudes, so a step to the left differs from a step forward.
* The joint weights ``M`` (feet/toes 4, knees/legs 2, hands 0.5, others 1 by name; overridden per
  exact joint name) apply to positions and velocities alike; ``velocity_weight`` scales the
  derivative terms (``L``).

An optional PCA rotation keeps the leading components holding ``>= variance`` of the total
variance (:func:`reduce_features`); the reduced distance is a lower bound of the full one, so a
caller screens candidates with it and recomputes exact costs (:func:`exact_costs`).
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from motion import Motion
from motion.features import torso_features
from motion.ground import body_joints
from motion.skeleton import Skeleton

from ..base import EngineError
from ..library import MotionLibrary

FloatArray = npt.NDArray[np.float64]
Float32Array = npt.NDArray[np.float32]
IntArray = npt.NDArray[np.int64]

GROUPS = ("positions", "velocities", "root_velocity", "root_acceleration", "turn_rate")
"""The feature groups, each normalised by its own database maximum frame step."""

_WEIGHT_RULES: tuple[tuple[re.Pattern[str], float], ...] = (
    (re.compile(r"foot|toe|ankle|heel", re.IGNORECASE), 4.0),
    (re.compile(r"knee|leg|shin|thigh|calf|femur|tibia", re.IGNORECASE), 2.0),
    (re.compile(r"hand|wrist|finger|thumb|index|pinky|ring|middle", re.IGNORECASE), 0.5),
)
_TINY = 1e-12
_CHUNK = 16384


@dataclass(frozen=True, slots=True)
class TransitionFeatures:
    """Transition features of every frame of a library (clips concatenated).

    Attributes
    ----------
    rows: ``(N, D)`` float32; ``C(a, b) = ||rows[a] - rows[b]||^2`` (dimensionless, see the module
        docstring). Centred on the database mean.
    offsets: ``(C + 1,)`` first row of each clip; ``offsets[-1] == N``.
    joints: names of the body joints compared.
    joint_weights: ``(K,)`` their weights.
    max_steps: per group (:data:`GROUPS`), the database maximum of the group's squared
        consecutive-frame difference in its own units (m^2, (m/s)^2, ..., before weighting by
        ``lam``); 0 for a group that never changes (then left out).
    mean_step: the average frame step's cost before the global factor ``k = 1 / mean_step``.
    """

    rows: Float32Array
    offsets: IntArray
    joints: tuple[str, ...]
    joint_weights: FloatArray
    max_steps: dict[str, float]
    mean_step: float

    @property
    def clip_of_row(self) -> IntArray:
        """``(N,)`` clip index of each row."""
        counts = np.diff(self.offsets)
        return np.repeat(np.arange(counts.size, dtype=np.int64), counts)


def default_joint_weight(name: str) -> float:
    """Weight of a joint by its name: feet/toes/ankles 4, knees/legs 2, hands/fingers 0.5, else 1."""
    for pattern, weight in _WEIGHT_RULES:
        if pattern.search(name):
            return weight
    return 1.0


def resolve_joint_weights(
    skeleton: Skeleton, joints: npt.NDArray[np.intp], overrides: Mapping[str, float] | None = None
) -> FloatArray:
    """``(K,)`` weights of ``joints``: :func:`default_joint_weight`, then ``overrides`` by exact
    joint name. Raises :class:`EngineError` for an override naming no joint or a negative weight."""
    names = [skeleton.names[j] for j in joints]
    weights = np.array([default_joint_weight(n) for n in names], dtype=np.float64)
    for name, value in (overrides or {}).items():
        if name not in skeleton.names:
            raise EngineError(
                f"joint_weights names joint {name!r}, which the skeleton does not have; "
                f"joints: {', '.join(skeleton.names)}"
            )
        if not np.isfinite(value) or value < 0:
            raise EngineError(f"joint_weights[{name!r}] must be a finite number >= 0, got {value}")
        if name in names:
            weights[names.index(name)] = float(value)
    if not np.any(weights > 0):
        raise EngineError("every joint weight is 0: the transition cost would compare nothing")
    return weights


def _raw_groups(
    motion: Motion, joints: npt.NDArray[np.intp], sqrt_w: FloatArray, positions: FloatArray | None
) -> list[FloatArray]:
    """The five groups of one clip, joint-weighted but not normalised: ``[(F, 3K), (F, 3K), (F, 3),
    (F, 3), (F, 1)]``."""
    tf = torso_features(motion, joints, positions)
    f = motion.num_frames
    return [
        (tf.positions * sqrt_w[None, :, None]).reshape(f, -1),
        (tf.velocities * sqrt_w[None, :, None]).reshape(f, -1),
        tf.root_velocity,
        tf.root_acceleration,
        tf.turn_rate[:, None],
    ]


def transition_features(
    library: MotionLibrary,
    joint_weights: Mapping[str, float] | None = None,
    velocity_weight: float = 1.0,
    positions: Sequence[FloatArray] | None = None,
) -> TransitionFeatures:
    """Transition features of every frame of ``library`` (see the module docstring).

    Parameters
    ----------
    library: clips at one rate, in metres, sharing one hierarchy.
    joint_weights: per exact joint name, overriding the defaults (feet 4, legs 2, hands 0.5, else 1).
    velocity_weight: weight ``lam`` of the derivative terms (joint velocities, root acceleration).
    positions: each clip's ``global_positions()`` when already computed (saves forward kinematics).

    Examples
    --------
    >>> from engines.library import MotionLibrary
    >>> from tests.motion.synthetic import walking_biped
    >>> lib = MotionLibrary(("w",), (walking_biped(90),), ((),))
    >>> tf = transition_features(lib)
    >>> steps = np.sum(np.diff(tf.rows.astype(np.float64), axis=0) ** 2, axis=1)
    >>> tf.rows.shape[0], round(float(steps.mean()), 3)
    (90, 1.0)
    """
    if not np.isfinite(velocity_weight) or velocity_weight < 0:
        raise EngineError(f"velocity_weight must be >= 0, got {velocity_weight}")
    skeleton = library.motions[0].skeleton
    joints = body_joints(skeleton)
    weights = resolve_joint_weights(skeleton, joints, joint_weights)
    sqrt_w = np.sqrt(weights)
    per_clip = [
        _raw_groups(m, joints, sqrt_w, None if positions is None else positions[i])
        for i, m in enumerate(library.motions)
    ]
    counts = np.array([m.num_frames for m in library.motions], dtype=np.int64)
    offsets = np.concatenate(([0], np.cumsum(counts))).astype(np.int64)

    lam = (1.0, velocity_weight, 1.0, velocity_weight, 1.0)
    max_steps: dict[str, float] = {}
    scales: list[FloatArray] = []
    for g, name in enumerate(GROUPS):
        step = max(
            (float(np.max(np.sum(np.diff(c[g], axis=0) ** 2, axis=1))) for c in per_clip if len(c[g]) > 1),
            default=0.0,
        )
        max_steps[name] = step
        scale = np.sqrt(lam[g] / step) if step > _TINY else 0.0
        scales.append(np.full(per_clip[0][g].shape[1], scale))
    scale_row = np.concatenate(scales)
    total = int(counts.sum())
    mean = sum(np.concatenate([b.sum(axis=0) for b in clip]) for clip in per_clip) / max(total, 1)
    # one clip at a time: memory holds the raw groups and the float32 rows, no full float64 copy
    rows = np.empty((total, scale_row.size), dtype=np.float32)
    step_sum, step_count = 0.0, 0
    for i, clip in enumerate(per_clip):
        block = (np.concatenate(clip, axis=1) - mean) * scale_row
        if block.shape[0] > 1:
            step_sum += float(np.sum(np.diff(block, axis=0) ** 2))
            step_count += block.shape[0] - 1
        rows[offsets[i] : offsets[i + 1]] = block
    mean_step = step_sum / step_count if step_count else 0.0
    if mean_step > _TINY:
        rows *= np.float32(1.0 / np.sqrt(mean_step))
    return TransitionFeatures(
        rows,
        offsets,
        tuple(skeleton.names[j] for j in joints),
        weights,
        max_steps,
        mean_step,
    )


def reduce_features(rows: Float32Array, variance: float = 0.999) -> tuple[Float32Array, float]:
    """PCA rotation of centred ``rows (N, D)`` onto the leading components holding at least
    ``variance`` of the total variance: ``(N, D')`` float32 and the fraction actually kept.

    Distances of the reduced rows are lower bounds of the full ones (the dropped components only
    add), and the squared error of a pair is at most the pair's own distance along the dropped
    components (on average twice the dropped variance)."""
    if not 0 < variance <= 1:
        raise EngineError(f"PCA variance must be in (0, 1], got {variance}")
    cov = np.zeros((rows.shape[1], rows.shape[1]))
    for i in range(0, rows.shape[0], _CHUNK):  # float64 sums, one chunk of float64 rows at a time
        x = rows[i : i + _CHUNK].astype(np.float64)
        cov += x.T @ x
    evals, evecs = np.linalg.eigh(cov)
    order = np.argsort(evals)[::-1]
    evals, evecs = np.clip(evals[order], 0.0, None), evecs[:, order]
    total = float(evals.sum())
    if total <= 0:
        return rows[:, :1].copy(), 1.0
    cum = np.cumsum(evals) / total
    k = int(np.searchsorted(cum, variance - 1e-12) + 1)
    k = min(max(k, 1), rows.shape[1])
    return rows @ evecs[:, :k].astype(np.float32), float(cum[k - 1])


def exact_costs(rows: Float32Array, a: IntArray, b: IntArray, chunk: int = 65536) -> FloatArray:
    """``C(a, b)`` for pairs of rows, from differences (no cancellation), in chunks of ``chunk``
    pairs (float32 arithmetic: relative error ~1e-6)."""
    out = np.empty(a.size, dtype=np.float64)
    for i in range(0, a.size, chunk):
        d = rows[a[i : i + chunk]] - rows[b[i : i + chunk]]
        out[i : i + chunk] = np.einsum("ij,ij->i", d, d)
    return out
