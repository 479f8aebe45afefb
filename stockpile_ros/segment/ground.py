"""Open ground that follows the site: bare patches wider than any rock, at any height.

The ground plane ``z = 0`` is a fit; a real site rises and falls under and round a pile, and
ground lifted off the plane by more than the ground tolerance was searched as rock (on a bed over
ground waving by a largest rock's b, the ground round it came out as one rock metres wide). What
tells open ground from rocks at any height is its width: a rock is nowhere wider than its own b,
and open ground is a surface on which a square wider than every rock lies flat.

So the surface is taken from above on a grid of ``cell`` (its lowest point per cell), and its
lower envelope is a grey opening ``window`` wide: the highest a dome that wide (see ``SHEET``) can
be pushed up from below, which goes into no rock narrower than it and follows ground that curves
more gently than the dome. A point is ground where it lies within ``tolerance`` of that envelope in
a connected patch of such cells that holds a ``window`` square (``RESTING`` of it): the floors of
the narrow crevices between rocks also touch the envelope, and they are not ground.

The dome must rest on the surface: past the edge of a survey nothing holds it up, and a dome
hanging out over the edge would rest on the top of whatever rock lies there (``RESTING``). Cells
no point fell in within ``HOLE_CELLS`` of one that did are gaps of the sampling and take that
cell's height; farther ones are outside the survey.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from scipy import ndimage

F64 = npt.NDArray[np.float64]

__all__ = ['HOLE_CELLS', 'RESTING', 'SHEET', 'open_ground']

HOLE_CELLS = 2
"""Widest gap between sampled cells that is still surface [cells]."""

SHEET = 0.1
"""Thickness over width of the flattest rock (``MeasureParams.min_thickness``). The envelope is
pushed up with a dome a window wide that falls ``SHEET / 2`` of the window along each axis at its
rim: it follows ground curving up to ``4 SHEET / window`` along an axis, and a rock as wide as
the window that stands more than that fall above its ground keeps it out (a narrower rock is kept
out at a lower height still). Measured on bench/bench_yardstick.py's riprap bed on ground waving
by half the largest b (window 1.875 m): a flat square found 55 % of the bare ground off the plane,
the dome 74 % (a fall of ``SHEET / 4`` 70 %), calling 0.18 % of rock faces ground."""

RESTING = 0.9
"""Least share of a window's area on the survey for the dome to bound the surface from below (a
rock at the survey's edge narrower than this share of the window cannot hold it up alone), and on
the envelope or past the survey's edge for a patch to be open ground."""


def _parabolic(z: F64, half: int, drop: float, erode: bool, axis: int) -> F64:
    """Erode (or dilate) ``z`` along one axis with a parabola ``half`` cells each way."""
    out: F64 = z.copy()
    n = z.shape[axis]
    pick, sign = (np.minimum, 1.0) if erode else (np.maximum, -1.0)
    for d in range(1, min(half, n - 1) + 1):
        bend = sign * drop * (d / half) ** 2
        lo, hi = [slice(None)] * 2, [slice(None)] * 2
        lo[axis], hi[axis] = slice(0, n - d), slice(d, n)
        out[tuple(lo)] = pick(out[tuple(lo)], z[tuple(hi)] + bend)
        out[tuple(hi)] = pick(out[tuple(hi)], z[tuple(lo)] + bend)
    return out


def _opening(z: F64, half: int, drop: float, outside: npt.NDArray[np.bool_]) -> F64:
    """Open ``z`` with a dome ``2 half + 1`` cells wide that falls ``drop`` at its edges.

    Only placements resting at least ``RESTING`` on the survey bound the surface from below.
    """
    side = 2 * half + 1
    eroded = np.where(outside, np.inf, z)
    for axis in (0, 1):
        eroded = _parabolic(eroded, half, drop, True, axis)
    resting = ndimage.uniform_filter((~outside).astype(np.float64), size=side, mode='constant')
    eroded[resting < RESTING - 1e-9] = -np.inf
    for axis in (0, 1):
        eroded = _parabolic(eroded, half, drop, False, axis)
    return eroded


def open_ground(
    points: npt.ArrayLike, window: float, cell: float, tolerance: float
) -> npt.NDArray[np.bool_]:
    """Which points lie on open ground (see the module documentation).

    Args:
        points: Nx3 positions, z up [m].
        window: Side of the square open ground must hold, wider than the largest rock's b [m].
        cell: Grid cell seen from above [m]; about the mesh's edge length.
        tolerance: Height over the lower envelope under which a point is on it [m].

    Returns:
        N booleans; all False when ``window`` or ``cell`` is not positive or there is no point.

    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if window <= 0 or cell <= 0 or not len(p):
        return np.zeros(len(p), dtype=bool)
    ij = np.floor((p[:, :2] - p[:, :2].min(axis=0)) / cell).astype(np.int64)
    shape = tuple(int(n) for n in ij.max(axis=0) + 1)
    flat = ij[:, 0] * shape[1] + ij[:, 1]
    order = np.argsort(flat, kind='stable')
    cells, starts = np.unique(flat[order], return_index=True)
    lowest = np.full(shape[0] * shape[1], np.inf)
    lowest[cells] = np.minimum.reduceat(p[order, 2], starts)
    low = lowest.reshape(shape)
    empty = np.isinf(low)
    distance, (ni, nj) = ndimage.distance_transform_edt(empty, return_indices=True)
    low = low[ni, nj]
    outside = distance > HOLE_CELLS
    half = round(window / (2 * cell))
    envelope = _opening(low, half, SHEET * window / 2, outside)
    near = ~outside
    near[near] = low[near] - envelope[near] <= tolerance
    # Past the survey's edge nothing contradicts a patch.
    wide = ndimage.minimum_filter(
        (near | outside).view(np.uint8), size=2 * half + 1, mode='nearest'
    )
    parts, _ = ndimage.label(near)
    patch = np.isin(parts, np.unique(parts[wide.astype(bool) & (parts > 0)]))
    on: npt.NDArray[np.bool_] = patch.ravel()[flat] & (
        p[:, 2] - envelope.ravel()[flat] <= tolerance
    )
    return on
