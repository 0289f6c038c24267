"""Rotations of a rigid particle about an axis through a pivot, given by (cos phi, sin phi).

The paper (section 3.2.2) avoids inverse trigonometric functions: a rotation is carried by
the pair ``(cos phi, sin phi)`` obtained from scalar and vector products (eqs. 13-14), and
a point ``r`` is moved by eq. 15 (Rodrigues' formula about the unit axis ``n`` through the
pivot ``p``)::

    r' = p + (1 - cos phi) (n . (r - p)) n + cos phi (r - p) + sin phi n x (r - p)

Eq. 14 as printed is ambiguous about the order of the cross product; the sign convention
used here is the right-hand rule about ``n``::

    cos phi = (x - O) . (x' - O) / (|x - O| |x' - O|)
    sin phi = n . ((x - O) x (x' - O)) / (|x - O| |x' - O|)

for a point ``x`` taken to ``x'`` (``O`` its projection on the axis), so that eq. 15 with
this pair maps ``x`` to ``x'``.

Orientations are unit quaternions ``(w, x, y, z)``; the quaternion of a rotation is built
from ``(cos phi, sin phi)`` by half-angle formulas that keep full relative precision for
small angles (``sin(phi/2) = sin phi / (2 cos(phi/2))`` when ``cos phi >= 0``).
"""

import math

import numpy as np

from parsim.core.jit import jit

__all__ = [
    "rotate_point",
    "cos_sin_about",
    "quat_from_axis_cos_sin",
    "quat_mul",
    "quat_normalize",
    "quat_to_matrix",
    "matrix_to_quat",
]


@jit(inline="always")
def rotate_point(x, pivot, axis, c, s, out):
    """Eq. 15: rotate point ``x`` about the unit ``axis`` through ``pivot``; writes ``out``."""
    r0 = x[0] - pivot[0]
    r1 = x[1] - pivot[1]
    r2 = x[2] - pivot[2]
    n0 = axis[0]
    n1 = axis[1]
    n2 = axis[2]
    nr = n0 * r0 + n1 * r1 + n2 * r2
    k = (1.0 - c) * nr
    out[0] = pivot[0] + k * n0 + c * r0 + s * (n1 * r2 - n2 * r1)
    out[1] = pivot[1] + k * n1 + c * r1 + s * (n2 * r0 - n0 * r2)
    out[2] = pivot[2] + k * n2 + c * r2 + s * (n0 * r1 - n1 * r0)


@jit
def cos_sin_about(x, x_new, origin, axis):
    """Eqs. 13-14: ``(cos phi, sin phi)`` of the rotation about ``axis`` taking ``x`` to ``x_new``.

    ``origin`` is a point of the axis; both ``x - origin`` and ``x_new - origin`` are
    projected on the plane normal to the axis first (so any point of the axis will do).
    """
    a = np.empty(3)
    b = np.empty(3)
    ha = 0.0
    hb = 0.0
    for k in range(3):
        a[k] = x[k] - origin[k]
        b[k] = x_new[k] - origin[k]
        ha += a[k] * axis[k]
        hb += b[k] * axis[k]
    for k in range(3):
        a[k] -= ha * axis[k]
        b[k] -= hb * axis[k]
    na = math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])
    nb = math.sqrt(b[0] * b[0] + b[1] * b[1] + b[2] * b[2])
    if na == 0.0 or nb == 0.0:
        return 1.0, 0.0
    c = (a[0] * b[0] + a[1] * b[1] + a[2] * b[2]) / (na * nb)
    s = (axis[0] * (a[1] * b[2] - a[2] * b[1]) + axis[1] * (a[2] * b[0] - a[0] * b[2])
         + axis[2] * (a[0] * b[1] - a[1] * b[0])) / (na * nb)
    return c, s


@jit(inline="always")
def quat_from_axis_cos_sin(axis, c, s, out):
    """Unit quaternion of the rotation by ``phi`` about the unit ``axis``, from ``(cos, sin)``."""
    if c >= 0.0:
        ch = math.sqrt(0.5 * (1.0 + c))
        sh = s / (2.0 * ch)
    else:
        sh = math.sqrt(0.5 * (1.0 - c))
        if s < 0.0:
            sh = -sh
        ch = s / (2.0 * sh) if sh != 0.0 else 0.0
    out[0] = ch
    out[1] = sh * axis[0]
    out[2] = sh * axis[1]
    out[3] = sh * axis[2]


@jit(inline="always")
def quat_mul(a, b, out):
    """Hamilton product ``out = a b`` (apply ``b`` first, then ``a``); ``out`` may alias neither."""
    aw, ax, ay, az = a[0], a[1], a[2], a[3]
    bw, bx, by, bz = b[0], b[1], b[2], b[3]
    out[0] = aw * bw - ax * bx - ay * by - az * bz
    out[1] = aw * bx + ax * bw + ay * bz - az * by
    out[2] = aw * by - ax * bz + ay * bw + az * bx
    out[3] = aw * bz + ax * by - ay * bx + az * bw


@jit(inline="always")
def quat_normalize(q):
    """Scale ``q`` to unit length in place (``w >= 0`` is not enforced)."""
    n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    for k in range(4):
        q[k] /= n


@jit(inline="always")
def quat_to_matrix(q, m):
    """Rotation matrix of the unit quaternion ``q = (w, x, y, z)`` into ``m`` (3, 3)."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    m[0, 0] = 1.0 - 2.0 * (y * y + z * z)
    m[0, 1] = 2.0 * (x * y - w * z)
    m[0, 2] = 2.0 * (x * z + w * y)
    m[1, 0] = 2.0 * (x * y + w * z)
    m[1, 1] = 1.0 - 2.0 * (x * x + z * z)
    m[1, 2] = 2.0 * (y * z - w * x)
    m[2, 0] = 2.0 * (x * z - w * y)
    m[2, 1] = 2.0 * (y * z + w * x)
    m[2, 2] = 1.0 - 2.0 * (x * x + y * y)


@jit
def matrix_to_quat(m, q):
    """Unit quaternion of a rotation matrix (Shepperd's method), ``w >= 0``."""
    tr = m[0, 0] + m[1, 1] + m[2, 2]
    if tr > 0.0:
        s = 2.0 * math.sqrt(tr + 1.0)
        q[0] = 0.25 * s
        q[1] = (m[2, 1] - m[1, 2]) / s
        q[2] = (m[0, 2] - m[2, 0]) / s
        q[3] = (m[1, 0] - m[0, 1]) / s
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        q[0] = (m[2, 1] - m[1, 2]) / s
        q[1] = 0.25 * s
        q[2] = (m[0, 1] + m[1, 0]) / s
        q[3] = (m[0, 2] + m[2, 0]) / s
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        q[0] = (m[0, 2] - m[2, 0]) / s
        q[1] = (m[0, 1] + m[1, 0]) / s
        q[2] = 0.25 * s
        q[3] = (m[1, 2] + m[2, 1]) / s
    else:
        s = 2.0 * math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        q[0] = (m[1, 0] - m[0, 1]) / s
        q[1] = (m[0, 2] + m[2, 0]) / s
        q[2] = (m[1, 2] + m[2, 1]) / s
        q[3] = 0.25 * s
    if q[0] < 0.0:
        for k in range(4):
            q[k] = -q[k]
    quat_normalize(q)
