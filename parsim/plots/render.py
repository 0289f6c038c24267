"""Pictures of many spheres: an orthographic, z-buffered, shaded rendering as one image.

One image instead of one vector circle per sphere keeps a sediment of 10^5-10^6 spheres
fast to draw and small as a PDF.
"""

import numpy as np
from matplotlib.colors import hsv_to_rgb

LIGHT = np.array([-0.4, 0.6, 0.7]) / np.linalg.norm([-0.4, 0.6, 0.7])  # (u, v, towards the viewer)
AMBIENT = 0.35  # brightness of a surface facing away from the light
CANDIDATES_PER_CHUNK = 2_000_000  # (sphere, pixel) pairs held at once: about 100 MB of work arrays
GOLDEN_RATIO_STEP = 0.618033988749895
SATURATION, VALUE = 0.55, 0.95
IMAGE_PIXELS = 900  # along the longer side of a picture
MAX_PIXELS_PER_RADIUS = 8  # finer shading costs time without showing more


def distinct_colours(labels: np.ndarray) -> np.ndarray:
    """An RGB colour per label; consecutive labels lie far apart in hue (golden-ratio steps)."""
    hue = (np.asarray(labels, dtype=np.float64) * GOLDEN_RATIO_STEP) % 1.0
    return hsv_to_rgb(np.column_stack([hue, np.full_like(hue, SATURATION), np.full_like(hue, VALUE)]))


def render_spheres(u, v, depth, radius, colours):
    """Spheres seen along the depth axis (smaller depth in front) as an RGBA image, and its extent.

    ``u``, ``v`` are the centres' coordinates in the image plane.  The picture is
    IMAGE_PIXELS wide along its longer side, or coarser where that would put more than
    MAX_PIXELS_PER_RADIUS pixels across a radius.  Each pixel shows the sphere whose
    surface is nearest the viewer at the pixel's centre, lit by a Lambertian light;
    uncovered pixels are transparent.  Returns (image (rows, columns, 4), (u0, u1, v0, v1)) for ``imshow``
    with ``origin="lower"``.
    """
    u, v, depth, radius = (np.asarray(a, dtype=np.float64) for a in (u, v, depth, radius))
    lower = np.array([np.min(u - radius), np.min(v - radius)])
    size = np.array([np.max(u + radius), np.max(v + radius)]) - lower
    pixel = max(size.max() / IMAGE_PIXELS, radius.max() / MAX_PIXELS_PER_RADIUS)
    columns, rows = (np.ceil(size / pixel).astype(int) + 1).tolist()
    nearest = np.full(rows * columns, np.inf)
    owner = np.full(rows * columns, -1)
    reach = int(np.ceil(radius.max() / pixel))
    step_u, step_v = (a.ravel() for a in np.meshgrid(np.arange(-reach, reach + 1), np.arange(-reach, reach + 1)))
    chunk = max(1, CANDIDATES_PER_CHUNK // step_u.size)
    for start in range(0, len(u), chunk):
        spheres = np.arange(start, min(start + chunk, len(u)))
        _paint(spheres, u, v, depth, radius, lower, pixel, columns, step_u, step_v, nearest, owner)
    image = _shade(owner, u, v, radius, colours, lower, pixel, columns).reshape(rows, columns, 4)
    return image, (lower[0], lower[0] + columns * pixel, lower[1], lower[1] + rows * pixel)


def _paint(spheres, u, v, depth, radius, lower, pixel, columns, step_u, step_v, nearest, owner) -> None:
    """Let ``spheres`` claim the pixels where their surface is nearer than what is there."""
    i = np.floor((u[spheres] - lower[0]) / pixel).astype(np.int64)[:, None] + step_u
    j = np.floor((v[spheres] - lower[1]) / pixel).astype(np.int64)[:, None] + step_v
    offset_u = lower[0] + (i + 0.5) * pixel - u[spheres, None]
    offset_v = lower[1] + (j + 0.5) * pixel - v[spheres, None]
    height_squared = radius[spheres, None] ** 2 - offset_u**2 - offset_v**2
    inside = height_squared > 0.0  # pixel centre within the sphere's disc, so within the image
    flat = (j * columns + i)[inside]
    surface = (depth[spheres, None] - np.sqrt(np.where(inside, height_squared, 0.0)))[inside]
    sphere = np.broadcast_to(spheres[:, None], inside.shape)[inside]
    order = np.lexsort((surface, flat))  # per pixel, the nearest surface first
    flat, surface, sphere = flat[order], surface[order], sphere[order]
    first = np.concatenate([[True], flat[1:] != flat[:-1]])
    flat, surface, sphere = flat[first], surface[first], sphere[first]
    closer = surface < nearest[flat]
    nearest[flat[closer]] = surface[closer]
    owner[flat[closer]] = sphere[closer]


def _shade(owner, u, v, radius, colours, lower, pixel, columns) -> np.ndarray:
    """RGBA per pixel: the owner's colour times the light on its surface normal there."""
    image = np.zeros((len(owner), 4))
    covered = np.flatnonzero(owner >= 0)
    sphere = owner[covered]
    offset_u = lower[0] + (covered % columns + 0.5) * pixel - u[sphere]
    offset_v = lower[1] + (covered // columns + 0.5) * pixel - v[sphere]
    towards_viewer = np.sqrt(np.maximum(radius[sphere] ** 2 - offset_u**2 - offset_v**2, 0.0))
    normal = np.column_stack([offset_u, offset_v, towards_viewer]) / radius[sphere, None]
    brightness = AMBIENT + (1.0 - AMBIENT) * np.clip(normal @ LIGHT, 0.0, None)
    image[covered, :3] = np.asarray(colours)[sphere] * brightness[:, None]
    image[covered, 3] = 1.0
    return image
