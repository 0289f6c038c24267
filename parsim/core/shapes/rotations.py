"""Uniform random orientations and the rotation of offsets by unit quaternions.

Quaternions are ``(w, x, y, z)`` with ``w`` the scalar part; :func:`rotate` applies the
active rotation ``v -> q v q*`` to row vectors.
"""

import numpy as np

from parsim.core.shapes.checks import _check_int

# Quaternions passed to rotate() must have |q| within this of 1.
QUATERNION_NORM_ATOL = 1e-6


def random_rotations(n, rng):
    """``n`` uniformly distributed unit quaternions ``(w, x, y, z)``, shape (n, 4).

    Shoemake's method ("Uniform random rotations", Graphics Gems III, 1992): with
    ``u1, u2, u3`` uniform on [0, 1), ``q = (sqrt(u1) cos 2pi u3, sqrt(1-u1) sin 2pi u2,
    sqrt(1-u1) cos 2pi u2, sqrt(u1) sin 2pi u3)`` is uniform on the unit 3-sphere, hence the
    rotation is uniform (Haar) on SO(3).  Uses ``rng.random((n, 3))`` only.
    """
    return np.asarray(DrawnRotations.draw(n, rng))


class DrawnRotations:
    """:func:`random_rotations` drawn but not yet computed: the uniforms are drawn at once (the
    generator's stream goes on as for :func:`random_rotations`), the quaternions of the rows asked
    for only when asked: ``rotations[rows]`` gives those rows of :func:`random_rotations`, bit for
    bit, and ``numpy.asarray(rotations)`` all of them.  A rank of a deposition spread over ranks
    draws every particle's orientation, to keep the stream, and computes only its own."""

    def __init__(self, uniforms):
        self.uniforms = uniforms

    @classmethod
    def draw(cls, n, rng) -> "DrawnRotations":
        n = _check_int("n", n, 0)
        if not isinstance(rng, np.random.Generator):
            raise ValueError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
        return cls(rng.random((n, 3)))

    def __len__(self):
        return len(self.uniforms)

    @property
    def shape(self):
        return (len(self.uniforms), 4)

    def __getitem__(self, rows) -> np.ndarray:
        return _shoemake(np.atleast_2d(self.uniforms[rows]))

    def __array__(self, dtype=None, copy=None):
        quaternions = _shoemake(self.uniforms)
        return quaternions if dtype is None else quaternions.astype(dtype, copy=False)


def _shoemake(u):
    """The unit quaternions of Shoemake's method for the rows of uniforms ``u`` (k, 3)."""
    a = np.sqrt(1.0 - u[:, 0])
    b = np.sqrt(u[:, 0])
    t2 = 2.0 * np.pi * u[:, 1]
    t3 = 2.0 * np.pi * u[:, 2]
    q = np.empty((len(u), 4))  # filled column by column: no temporaries to stack
    np.multiply(b, np.cos(t3), out=q[:, 0])
    np.multiply(a, np.sin(t2), out=q[:, 1])
    np.multiply(a, np.cos(t2), out=q[:, 2])
    np.multiply(b, np.sin(t3), out=q[:, 3])
    return q


def rotate(offsets, quaternion):
    """Rotate row vectors by a unit quaternion ``(w, x, y, z)``: ``v -> q v q*``.

    ``offsets`` (k, 3); returns a new (k, 3) array ``offsets @ R.T`` with ``R`` the
    rotation matrix of ``q``.  ``|q|`` must be 1 within ``QUATERNION_NORM_ATOL``; it is
    normalised before use.
    """
    try:
        v = np.array(offsets, dtype=np.float64)
        q = np.array(quaternion, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError("offsets must be a (k, 3) and quaternion a (4,) numeric array") from None
    if v.ndim != 2 or v.shape[1] != 3:
        raise ValueError(f"offsets must have shape (k, 3), got {v.shape}")
    if q.shape != (4,) or not np.all(np.isfinite(q)):
        raise ValueError(f"quaternion must be 4 finite numbers (w, x, y, z), got shape {q.shape}")
    norm = float(np.sqrt(np.sum(q * q)))
    if abs(norm - 1.0) > QUATERNION_NORM_ATOL:
        raise ValueError(f"quaternion must have unit norm (within {QUATERNION_NORM_ATOL}), got {norm!r}")
    w, x, y, z = q / norm
    R = np.array(
        [
            [1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - z * w), 2.0 * (x * z + y * w)],
            [2.0 * (x * y + z * w), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - x * w)],
            [2.0 * (x * z - y * w), 2.0 * (y * z + x * w), 1.0 - 2.0 * (x * x + y * y)],
        ]
    )
    return v @ R.T
