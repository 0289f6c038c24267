"""Argument checks shared by the shape builders (each raises ValueError naming the argument)."""

import math

import numpy as np

# Relative tolerance on "spacing <= 2 radius" (connected chains), to admit 2r up to round-off.
SPACING_RTOL = 1e-12


def _check_int(name, value, minimum):
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)


def _check_positive(name, value):
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a finite number > 0, got {value!r}") from None
    if not (math.isfinite(v) and v > 0.0):
        raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
    return v


def _check_spacing(spacing, radius):
    spacing = _check_positive("spacing", spacing)
    if spacing > 2.0 * radius * (1.0 + SPACING_RTOL):
        raise ValueError(
            f"spacing must be in (0, 2 * radius] = (0, {2.0 * radius!r}] so that neighbouring "
            f"spheres overlap or touch, got {spacing!r}"
        )
    return spacing


def _check_centres_radii(centres, radii, allow_2d):
    try:
        c = np.array(centres, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError("centres must be a numeric array of shape (n, 3)") from None
    dims = (2, 3) if allow_2d else (3,)
    if c.ndim != 2 or c.shape[1] not in dims or c.shape[0] < 1:
        allowed = "(n, 2) or (n, 3)" if allow_2d else "(n, 3)"
        raise ValueError(f"centres must have shape {allowed} with n >= 1, got {c.shape}")
    if not np.all(np.isfinite(c)):
        raise ValueError("centres must be finite (no NaN or inf)")
    try:
        r = np.array(radii, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"radii must be a numeric array of shape ({c.shape[0]},)") from None
    if r.shape != (c.shape[0],):
        raise ValueError(f"radii must have shape ({c.shape[0]},) to match centres, got {r.shape}")
    if not np.all(np.isfinite(r)) or np.any(r <= 0.0):
        raise ValueError(f"radii must be finite and > 0, got min {np.nanmin(r)!r}")
    if c.shape[1] == 2:
        c = np.hstack([c, np.zeros((c.shape[0], 1))])
    return np.ascontiguousarray(c), np.ascontiguousarray(r)
