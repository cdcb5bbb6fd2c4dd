"""Unit quaternions, vectorised over any leading shape.

Convention (glTF, three.js, scipy): a quaternion is ``(x, y, z, w)`` in the last axis, scalar last.
Products compose like rotation matrices: ``multiply(a, b)`` rotates by ``b`` first, then ``a``.
Euler angles follow BVH: intrinsic rotations in the written order (scipy's uppercase sequences),
degrees.
"""

from __future__ import annotations

import warnings

import numpy as np
import numpy.typing as npt
from scipy.spatial.transform import Rotation

from .errors import MotionError
from .vectors import cross, norms

Array = npt.NDArray[np.float64]

IDENTITY = np.array([0.0, 0.0, 0.0, 1.0])


def identity(shape: tuple[int, ...] = ()) -> Array:
    """Identity quaternions of shape ``shape + (4,)``."""
    out = np.zeros((*shape, 4))
    out[..., 3] = 1.0
    return out


def normalize(q: Array) -> Array:
    """Quaternions scaled to unit length; zero quaternions raise :class:`MotionError`."""
    n = norms(q)[..., None]
    if np.any(n < 1e-12):
        raise MotionError("zero-length quaternion cannot be normalised")
    return np.asarray(q / n)


def conjugate(q: Array) -> Array:
    """Inverse of unit quaternions."""
    out = np.array(q, dtype=np.float64, copy=True)
    out[..., :3] *= -1.0
    return out


inverse = conjugate


def multiply(a: Array, b: Array) -> Array:
    """Hamilton product ``a * b`` (apply ``b`` then ``a``), broadcasting leading axes."""
    ax, ay, az, aw = a[..., 0], a[..., 1], a[..., 2], a[..., 3]
    bx, by, bz, bw = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    out = np.empty(np.broadcast_shapes(np.shape(a), np.shape(b)), dtype=np.result_type(a, b, np.float64))
    out[..., 0] = aw * bx + ax * bw + ay * bz - az * by
    out[..., 1] = aw * by - ax * bz + ay * bw + az * bx
    out[..., 2] = aw * bz + ax * by - ay * bx + az * bw
    out[..., 3] = aw * bw - ax * bx - ay * by - az * bz
    return out


def rotate(q: Array, v: Array) -> Array:
    """Rotate vectors ``v (..., 3)`` by unit quaternions ``q (..., 4)`` (broadcasting)."""
    u = q[..., :3]
    w = q[..., 3:4]
    t = 2.0 * cross(u, v)
    return np.asarray(v + w * t + cross(u, t))


def to_matrix(q: Array) -> Array:
    """Rotation matrices ``(..., 3, 3)`` of unit quaternions ``(..., 4)``."""
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    m = np.empty((*q.shape[:-1], 3, 3))
    m[..., 0, 0] = 1 - 2 * (yy + zz)
    m[..., 0, 1] = 2 * (xy - wz)
    m[..., 0, 2] = 2 * (xz + wy)
    m[..., 1, 0] = 2 * (xy + wz)
    m[..., 1, 1] = 1 - 2 * (xx + zz)
    m[..., 1, 2] = 2 * (yz - wx)
    m[..., 2, 0] = 2 * (xz - wy)
    m[..., 2, 1] = 2 * (yz + wx)
    m[..., 2, 2] = 1 - 2 * (xx + yy)
    return m


def from_matrix(m: Array) -> Array:
    """Unit quaternions ``(..., 4)`` of rotation matrices ``(..., 3, 3)``."""
    shape = m.shape[:-2]
    q = Rotation.from_matrix(m.reshape(-1, 3, 3)).as_quat()
    return np.asarray(q.reshape(*shape, 4))


def from_axis_angle(axis: Array, angle: Array | float) -> Array:
    """Quaternions rotating by ``angle`` radians about unit ``axis (..., 3)``."""
    half = 0.5 * np.asarray(angle, dtype=np.float64)[..., None]
    return np.concatenate((np.asarray(axis) * np.sin(half), np.cos(half)), axis=-1)


def from_yaw(angle: Array | float) -> Array:
    """Rotations about +Y by ``angle`` radians (0 leaves +Z in place, +pi/2 takes +Z to +X)."""
    a = np.asarray(angle, dtype=np.float64)
    half = 0.5 * a
    out = np.zeros((*a.shape, 4))
    out[..., 1] = np.sin(half)
    out[..., 3] = np.cos(half)
    return out


def standardize(q: Array) -> Array:
    """The same rotations with ``w >= 0`` (each rotation has two quaternions, q and -q)."""
    return np.where(q[..., 3:4] < 0, -q, q)


def make_continuous(q: Array, axis: int = 0) -> Array:
    """Flip signs along ``axis`` (time) so consecutive quaternions lie in the same hemisphere."""
    q = np.moveaxis(np.array(q, dtype=np.float64, copy=True), axis, 0)
    if q.shape[0] > 1:
        dots = _dot4(q[1:], q[:-1])
        flips = np.cumsum(dots < 0, axis=0) % 2 == 1
        if flips.any():
            q[1:] *= np.where(flips, -1.0, 1.0)[..., None]
    return np.moveaxis(q, 0, axis)


def log(q: Array) -> Array:
    """Rotation vectors ``(..., 3)`` (axis * angle, radians; angle in [0, pi]) of unit quaternions."""
    q = standardize(q)
    v = q[..., :3]
    s = norms(v)
    angle = 2.0 * np.arctan2(s, q[..., 3])
    with np.errstate(invalid="ignore", divide="ignore"):
        scale = np.where(s > 1e-12, angle / np.where(s > 1e-12, s, 1.0), 2.0)
    return np.asarray(v * scale[..., None])


def exp(r: Array) -> Array:
    """Unit quaternions of rotation vectors ``r (..., 3)`` (inverse of :func:`log`)."""
    angle = norms(r)
    half = 0.5 * angle
    with np.errstate(invalid="ignore", divide="ignore"):
        k = np.where(angle > 1e-12, np.sin(half) / np.where(angle > 1e-12, angle, 1.0), 0.5)
    return np.concatenate((r * k[..., None], np.cos(half)[..., None]), axis=-1)


def angle_between(a: Array, b: Array) -> Array:
    """Rotation angle (radians, in [0, pi]) of ``a^-1 b``."""
    d = np.abs(np.sum(a * b, axis=-1))
    return np.asarray(2.0 * np.arccos(np.clip(d, 0.0, 1.0)))


def slerp(a: Array, b: Array, t: Array | float) -> Array:
    """Spherical interpolation from ``a`` (t=0) to ``b`` (t=1) along the shorter arc (broadcasting)."""
    t = np.asarray(t, dtype=np.float64)
    dot = _dot4(a, b)
    b = np.where((dot < 0)[..., None], -b, b)
    dot = np.abs(dot)
    theta = np.arccos(np.clip(dot, -1.0, 1.0))
    sin_theta = np.sin(theta)
    small = sin_theta < 1e-9
    safe = np.where(small, 1.0, sin_theta)
    wa = np.where(small, 1.0 - t, np.sin((1.0 - t) * theta) / safe)
    wb = np.where(small, t, np.sin(t * theta) / safe)
    out = wa[..., None] * a + wb[..., None] * b
    return np.asarray(out / norms(out)[..., None])


def _dot4(a: Array, b: Array) -> Array:
    """``np.sum(a * b, axis=-1)`` of quaternions (the products summed in the same order)."""
    return np.asarray(
        ((a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1]) + a[..., 2] * b[..., 2]) + a[..., 3] * b[..., 3]
    )


def from_euler(order: str, angles_deg: Array) -> Array:
    """Quaternions of intrinsic Euler angles (BVH convention).

    Parameters
    ----------
    order:
        Axis letters in channel order, e.g. ``"ZXY"`` (1 to 3 letters; case-insensitive): the
        rotation is ``R(order[0], a0) R(order[1], a1) R(order[2], a2)``.
    angles_deg:
        ``(..., len(order))`` degrees.
    """
    order = order.upper()
    angles = np.asarray(angles_deg, dtype=np.float64)
    if angles.shape[-1:] != (len(order),):
        raise MotionError(f"Euler angles for order {order!r} need a last axis of {len(order)}")
    comps = from_euler_components(order, [angles[..., k] for k in range(len(order))])
    return np.stack(comps, axis=-1)


_CYCLIC = {
    ("X", "Y"): ("Z", 1.0),
    ("Y", "Z"): ("X", 1.0),
    ("Z", "X"): ("Y", 1.0),
    ("Y", "X"): ("Z", -1.0),
    ("Z", "Y"): ("X", -1.0),
    ("X", "Z"): ("Y", -1.0),
}
_AXIS = {"X": 0, "Y": 1, "Z": 2}
_HALF_DEG = np.pi / 360.0


def _times_elemental(q: list[Array], axis: int, c: Array, s: Array) -> list[Array]:
    """``q * (cos + sin * e_axis)`` for a general quaternion given as components [x, y, z, w]."""
    a, b = (axis + 1) % 3, (axis + 2) % 3
    out = [q[0], q[1], q[2], q[3]]
    out[3] = c * q[3] - s * q[axis]
    out[axis] = c * q[axis] + s * q[3]
    out[a] = c * q[a] + s * q[b]
    out[b] = c * q[b] - s * q[a]
    return out


def from_euler_components(order: str, angles_deg: list[Array]) -> tuple[Array, Array, Array, Array]:
    """Quaternion components ``(x, y, z, w)`` of intrinsic Euler angles given per axis.

    ``angles_deg[k]`` holds the angles (degrees, any shape) about ``order[k]``. The product of the
    elemental rotations is written out (first two factors in closed form), ~25 elementwise ops.
    """
    order = order.upper()
    if not 1 <= len(order) <= 3 or any(a not in "XYZ" for a in order) or len(angles_deg) != len(order):
        raise MotionError(f"invalid Euler order {order!r} for {len(angles_deg)} angle arrays")
    c, s = [], []
    for a in angles_deg:
        a = np.asarray(a, dtype=np.float64)
        if a.size and np.abs(a).max() > 180.0:
            a = a - 360.0 * np.round(a / 360.0)  # same rotation; keeps the half angle in [-90, 90]
        sin_half = np.sin(a * _HALF_DEG)
        s.append(sin_half)
        # cos of a half angle in [-90, 90] degrees is >= 0; the sqrt form costs a tenth of np.cos
        # here (no SIMD float64 trig in our numpy builds) and is exact to a few ulp except near
        # +-90 degrees, where np.cos is used.
        cos_half = np.sqrt((1.0 - sin_half) * (1.0 + sin_half))
        steep = np.abs(sin_half) > 0.999  # half angle within ~2.6 degrees of +-90: sqrt loses digits
        if steep.any():
            cos_half[steep] = np.cos(a[steep] * _HALF_DEG)
        c.append(cos_half)
    zero = np.zeros_like(c[0])
    q: list[Array] = [zero, zero, zero, c[0]]
    q[_AXIS[order[0]]] = s[0]
    start = 1
    if len(order) >= 2 and order[1] != order[0]:
        third, sign = _CYCLIC[(order[0], order[1])]
        q = [zero, zero, zero, c[0] * c[1]]
        q[_AXIS[order[0]]] = s[0] * c[1]
        q[_AXIS[order[1]]] = c[0] * s[1]
        q[_AXIS[third]] = s[0] * s[1] if sign > 0 else -(s[0] * s[1])
        start = 2
    for k in range(start, len(order)):
        q = _times_elemental(q, _AXIS[order[k]], c[k], s[k])
    return q[0], q[1], q[2], q[3]


def wrap_angle(a: Array | float) -> Array:
    """Angles (radians) wrapped to ``[-pi, pi)``."""
    return np.asarray((np.asarray(a, dtype=np.float64) + np.pi) % (2.0 * np.pi) - np.pi)


def rotate_floor(theta: Array | float, xz: Array) -> Array:
    """Floor vectors ``xz (..., 2)`` ``[x, z]`` rotated by ``theta (...)`` radians about +Y (+Z
    turns towards +X at ``pi / 2``; the yaw convention of :func:`yaw`)."""
    th = np.asarray(theta, dtype=np.float64)
    return rotate_floor_by(np.cos(th), np.sin(th), xz[..., 0], xz[..., 1])


def rotate_floor_by(cos: Array, sin: Array, x: Array, z: Array) -> Array:
    """:func:`rotate_floor` with the angle's cosine and sine given (broadcast against ``x``, ``z``):
    for callers that take them once per piece of motion rather than once per frame."""
    return np.stack((cos * x + sin * z, -sin * x + cos * z), axis=-1)


def _wrap_deg(a: Array) -> Array:
    """Angles wrapped to (-180, 180]."""
    return np.asarray(180.0 - np.mod(180.0 - a, 360.0))


def to_euler(order: str, q: Array) -> Array:
    """Intrinsic Euler angles (degrees) in ``order`` for quaternions ``(..., 4)``.

    Three letters: scipy's decomposition (first and last angle in (-180, 180], middle in
    [-90, 90] for Tait-Bryan orders; at gimbal lock the last angle is set to zero). One letter:
    the signed angle about that axis. Two letters: of the two decompositions with a completing
    third axis, the one whose third angle is nearest zero, which is exact for rotations the two
    axes can express (as in any BVH file).
    """
    order = order.upper()
    if not 1 <= len(order) <= 3 or any(a not in "XYZ" for a in order):
        raise MotionError(f"invalid Euler order {order!r}")
    shape = q.shape[:-1]
    flat = np.asarray(q, dtype=np.float64).reshape(-1, 4)
    if len(order) == 1:
        angles = _wrap_deg(np.degrees(2.0 * np.arctan2(flat[:, _AXIS[order]], flat[:, 3])))[:, None]
        return np.asarray(angles.reshape(*shape, 1))
    full = order + ("" if len(order) == 3 else next(a for a in "XYZ" if a not in order))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # gimbal lock: handled as documented
        angles = Rotation.from_quat(flat).as_euler(full, degrees=True)
    if len(order) == 2:
        alt = np.stack(
            (
                _wrap_deg(angles[:, 0] + 180.0),
                _wrap_deg(180.0 - angles[:, 1]),
                _wrap_deg(angles[:, 2] + 180.0),
            ),
            axis=-1,
        )
        angles = np.where((np.abs(alt[:, 2]) < np.abs(angles[:, 2]))[:, None], alt, angles)[:, :2]
    return np.asarray(angles.reshape(*shape, len(order)))


def yaw(q: Array, forward: Array | None = None) -> Array:
    """Heading angle (radians) about +Y of the rotated ``forward`` axis (default +Z), projected on
    the floor: 0 = facing +Z, +pi/2 = facing +X."""
    f = np.array([0.0, 0.0, 1.0]) if forward is None else np.asarray(forward, dtype=np.float64)
    v = rotate(q, np.broadcast_to(f, (*q.shape[:-1], 3)))
    return np.asarray(np.arctan2(v[..., 0], v[..., 2]))
