"""Small 4x4 matrices and quaternions in plain Python (Blender's bundled Python has no numpy here).

A matrix is a tuple of 16 floats, row major (``m[4 * row + col]``), acting on column vectors
(``p' = M p``), as ``mathutils.Matrix`` does; a quaternion is ``(x, y, z, w)`` as in glTF.
These are for the slow paths (rest poses, a clip's conversion, tests); the add-on keys actions
with ``mathutils`` through the same formulas (:mod:`.binding`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

Mat4 = tuple[float, ...]
Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]

IDENTITY: Mat4 = (1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0)


def mat4(values: Sequence[float]) -> Mat4:
    """16 numbers, row major, as a matrix (``ValueError`` for another count)."""
    if len(values) != 16:
        raise ValueError(f"a 4x4 matrix has 16 numbers, not {len(values)}")
    return tuple(float(v) for v in values)


def from_rows(rows: Sequence[Sequence[float]]) -> Mat4:
    """A matrix from 4 rows of 4 numbers (``mathutils.Matrix`` rows, say)."""
    return mat4([float(v) for row in rows for v in row])


def from_column_major(values: Sequence[float]) -> Mat4:
    """A glTF ``matrix`` (16 numbers, column major) as a matrix."""
    return tuple(float(values[4 * c + r]) for r in range(4) for c in range(4))


def mul(a: Mat4, b: Mat4) -> Mat4:
    """The product ``a @ b``."""
    return tuple(
        a[4 * r] * b[c] + a[4 * r + 1] * b[4 + c] + a[4 * r + 2] * b[8 + c] + a[4 * r + 3] * b[12 + c]
        for r in range(4)
        for c in range(4)
    )


def inverse(m: Mat4) -> Mat4:
    """The inverse of an affine matrix (last row ``0 0 0 1``); ``ValueError`` when singular."""
    a, b, c, d, e, f, g, h, i = m[0], m[1], m[2], m[4], m[5], m[6], m[8], m[9], m[10]
    co = (e * i - f * h, c * h - b * i, b * f - c * e, f * g - d * i, a * i - c * g, c * d - a * f,
          d * h - e * g, b * g - a * h, a * e - b * d)  # fmt: skip
    det = a * co[0] + b * co[3] + c * co[6]
    if abs(det) < 1e-300:
        raise ValueError("the matrix is singular (a zero scale?)")
    k = 1.0 / det
    r = [x * k for x in co]  # rows of the 3x3 inverse
    t = (m[3], m[7], m[11])
    tx = -(r[0] * t[0] + r[1] * t[1] + r[2] * t[2])
    ty = -(r[3] * t[0] + r[4] * t[1] + r[5] * t[2])
    tz = -(r[6] * t[0] + r[7] * t[1] + r[8] * t[2])
    return (r[0], r[1], r[2], tx, r[3], r[4], r[5], ty, r[6], r[7], r[8], tz, 0.0, 0.0, 0.0, 1.0)


def from_trs(t: Sequence[float], q: Sequence[float], s: Sequence[float]) -> Mat4:
    """Translation, rotation ``(x, y, z, w)`` and scale as a matrix (``T R S``, as glTF)."""
    x, y, z, w = (float(v) for v in q)
    n = x * x + y * y + z * z + w * w
    k = 2.0 / n if n > 0 else 0.0
    xx, yy, zz, xy, xz, yz, wx, wy, wz = x * x * k, y * y * k, z * z * k, x * y * k, x * z * k, y * z * k, \
        w * x * k, w * y * k, w * z * k  # fmt: skip
    sx, sy, sz = (float(v) for v in s)
    return (
        (1 - yy - zz) * sx, (xy - wz) * sy, (xz + wy) * sz, float(t[0]),
        (xy + wz) * sx, (1 - xx - zz) * sy, (yz - wx) * sz, float(t[1]),
        (xz - wy) * sx, (yz + wx) * sy, (1 - xx - yy) * sz, float(t[2]),
        0.0, 0.0, 0.0, 1.0,
    )  # fmt: skip


def translation(m: Mat4) -> Vec3:
    """The translation column of ``m``."""
    return (m[3], m[7], m[11])


def apply(m: Mat4, p: Sequence[float]) -> Vec3:
    """``m`` applied to the point ``p``."""
    x, y, z = float(p[0]), float(p[1]), float(p[2])
    return (
        m[0] * x + m[1] * y + m[2] * z + m[3],
        m[4] * x + m[5] * y + m[6] * z + m[7],
        m[8] * x + m[9] * y + m[10] * z + m[11],
    )


def rotate(m: Mat4, v: Sequence[float]) -> Vec3:
    """``m``'s linear part applied to the direction ``v``."""
    x, y, z = float(v[0]), float(v[1]), float(v[2])
    return (m[0] * x + m[1] * y + m[2] * z, m[4] * x + m[5] * y + m[6] * z, m[8] * x + m[9] * y + m[10] * z)


def scale_of(m: Mat4) -> Vec3:
    """The lengths of ``m``'s three basis columns."""
    return (
        math.sqrt(m[0] ** 2 + m[4] ** 2 + m[8] ** 2),
        math.sqrt(m[1] ** 2 + m[5] ** 2 + m[9] ** 2),
        math.sqrt(m[2] ** 2 + m[6] ** 2 + m[10] ** 2),
    )


def rotation_of(m: Mat4) -> Quat:
    """The rotation of ``m`` with its column scales divided out, as ``(x, y, z, w)`` (``w >= 0``)."""
    sx, sy, sz = scale_of(m)
    r = (m[0] / sx, m[1] / sy, m[2] / sz, m[4] / sx, m[5] / sy, m[6] / sz, m[8] / sx, m[9] / sy, m[10] / sz)
    return quat_from_matrix3(r)


def quat_from_matrix3(r: Sequence[float]) -> Quat:
    """A rotation matrix (9 numbers, row major) as a unit quaternion ``(x, y, z, w)``, ``w >= 0``."""
    m00, m01, m02, m10, m11, m12, m20, m21, m22 = (float(v) for v in r)
    tr = m00 + m11 + m22
    if tr > 0:
        s = 0.5 / math.sqrt(tr + 1.0)
        q = ((m21 - m12) * s, (m02 - m20) * s, (m10 - m01) * s, 0.25 / s)
    elif m00 > m11 and m00 > m22:
        s = 2.0 * math.sqrt(1.0 + m00 - m11 - m22)
        q = (0.25 * s, (m01 + m10) / s, (m02 + m20) / s, (m21 - m12) / s)
    elif m11 > m22:
        s = 2.0 * math.sqrt(1.0 + m11 - m00 - m22)
        q = ((m01 + m10) / s, 0.25 * s, (m12 + m21) / s, (m02 - m20) / s)
    else:
        s = 2.0 * math.sqrt(1.0 + m22 - m00 - m11)
        q = ((m02 + m20) / s, (m12 + m21) / s, 0.25 * s, (m10 - m01) / s)
    n = math.sqrt(sum(c * c for c in q))
    x, y, z, w = (c / n for c in q)
    return (-x, -y, -z, -w) if w < 0 else (x, y, z, w)


def matrix3_of_quat(q: Sequence[float]) -> tuple[float, ...]:
    """A unit quaternion ``(x, y, z, w)`` as a rotation matrix (9 numbers, row major)."""
    m = from_trs((0.0, 0.0, 0.0), q, (1.0, 1.0, 1.0))
    return (m[0], m[1], m[2], m[4], m[5], m[6], m[8], m[9], m[10])


_AXES = {"X": 0, "Y": 1, "Z": 2}


def euler_from_matrix3(r: Sequence[float], order: str) -> Vec3:
    """Intrinsic Euler angles (radians) of a rotation matrix in ``order`` (e.g. ``"ZXY"``: R = Rz Rx
    Ry, the angles returned in that order), as BVH channels read them."""
    if sorted(order) != ["X", "Y", "Z"]:
        raise ValueError(f"an Euler order names X, Y and Z once each, not {order!r}")
    i, j, k = (_AXES[a] for a in order)
    parity = 1.0 if (j - i) % 3 == 1 else -1.0  # an even permutation of XYZ

    def at(row: int, col: int) -> float:
        return float(r[3 * row + col])

    # R = R_i(a) R_j(b) R_k(c): R[i][k] = +-sin(b)
    sb = max(-1.0, min(1.0, parity * at(i, k)))
    b = math.asin(sb)
    if abs(sb) < 1.0 - 1e-12:
        a = math.atan2(-parity * at(j, k), at(k, k))
        c = math.atan2(-parity * at(i, j), at(i, i))
    else:  # gimbal lock: put the whole turn about the first axis
        a = math.atan2(parity * at(k, j), at(j, j))
        c = 0.0
    return (a, b, c)


def matrix3_of_euler(angles: Sequence[float], order: str) -> tuple[float, ...]:
    """The rotation matrix (row major) of intrinsic Euler ``angles`` (radians) in ``order``."""
    out: tuple[float, ...] = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
    for axis, angle in zip(order, angles, strict=True):
        c, s = math.cos(angle), math.sin(angle)
        if axis == "X":
            step: tuple[float, ...] = (1.0, 0.0, 0.0, 0.0, c, -s, 0.0, s, c)
        elif axis == "Y":
            step = (c, 0.0, s, 0.0, 1.0, 0.0, -s, 0.0, c)
        else:
            step = (c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0)
        out = tuple(
            float(sum(out[3 * r + k] * step[3 * k + col] for k in range(3)))
            for r in range(3)
            for col in range(3)
        )
    return out
