"""Open ground that follows the site: bare patches wider than any rock, at any height.

The ground plane ``z = 0`` is a fit; a real site rises and falls under and round a pile, and
ground lifted off the plane by more than the ground tolerance was searched as rock (on a bed over
ground waving by a largest rock's b, the ground round it came out as one rock metres wide). What
tells open ground from rocks at any height is its width: a rock is nowhere wider than its own b,
and open ground is a surface on which a square wider than every rock lies flat.

So the surface is taken from above on a grid of ``cell`` (its lowest point per cell), and its
lower envelope is a grey opening ``window`` wide: the highest a dome that wide (see ``SHEET``) can
be pushed up from below, which goes into no rock narrower than it and follows ground that curves
more gently than the dome. Open ground is found where cells lie within ``tolerance`` of that
envelope in a connected patch that holds a ``window`` square (``RESTING`` of it): the floors of
the narrow crevices between rocks also touch the envelope, and they do not make a patch.

The dome must rest on the surface: past the edge of a survey nothing holds it up, and a dome
hanging out over the edge would rest on the top of whatever rock lies there (``RESTING``). Cells
no point fell in within ``HOLE_CELLS`` of one that did are gaps of the sampling and take that
cell's height; farther ones are outside the survey.

The dome cannot rise into ridges of the ground sharper than itself, and at fine meshes the ground
tolerance (a few edge lengths) is under what it leaves there. So the patches found are then
fitted with a smooth surface (a quadratic over a Gaussian neighbourhood ``TREND`` windows wide),
which bridges ridges from the ground found on both sides, and ground is taken again as the cells
within the tolerance of it that join ground already found, ``REFITS`` times. The fit reaches only
where found ground weighs at least ``SUPPORT`` of its neighbourhood, so it does not extrapolate
far under a pile. That surface is the ground where it reaches, in place of the plane: a face
within the tolerance of it is ground, and a rock's base rests on it.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from scipy import ndimage

F64 = npt.NDArray[np.float64]
Mask = npt.NDArray[np.bool_]

__all__ = [
    'FIT_CELLS',
    'FOOT_CELLS',
    'GRID_CELLS',
    'HOLE_CELLS',
    'REFITS',
    'RESTING',
    'SHEET',
    'SUPPORT',
    'TREND',
    'ground_height',
]

HOLE_CELLS = 2
"""Widest gap between sampled cells that is still surface [cells]."""

SHEET = 0.1
"""Thickness over width of the flattest rock (``MeasureParams.min_thickness``). The envelope is
pushed up with a dome a window wide that falls ``SHEET / 2`` of the window along each axis at its
rim: it follows ground curving up to ``4 SHEET / window`` along an axis, and a rock as wide as
the window that stands more than that fall above its ground keeps it out (a narrower rock is kept
out at a lower height still). Measured on bench/bench_yardstick.py's riprap bed on ground waving
by half the largest b at 12 edges across the smallest b (window 1.875 m), before the fit of
``TREND``: a flat square found 55 % of the bare ground off the plane, the dome 74 % (a fall of
``SHEET / 4`` 70 %), calling 0.18 % of rock faces ground."""

TREND = 0.25
"""Standard deviation of the neighbourhood the ground surface is fitted over [windows]: ground is
smooth over the width of the largest rock, and a quarter window sees both sides of a ridge no
wider than a rock. Measured on bench/bench_yardstick.py's riprap bed over ground waving by half
the largest b at 20 edges across the smallest b (window 1.875 m): the dome alone found 66 % of
the bare ground, the fit 96 % (a standard deviation of half a window 94 %), calling 0.06 % of
the rock faces ground."""

GRID_CELLS = 64
"""Cells per window of the coarsest grid the surface is taken on from above (the mesh's edge
length where that is finer): the opening's cost grows with the cells times the window's width in
cells. Measured on 5 M points over a 1.5 m square (aggregate, largest b 80 mm, meshed at 30
edges across its smallest b: 0.7 mm edges): 15 s at the edge length, 1.9 s with this grid; on 1 M
points over 15 m (riprap at 20 edges) 1.8 s and 0.4 s. The bare ground found on the riprap bed
of ``TREND`` rose from 95.5 % to 96.3 %."""

FIT_CELLS = 16
"""Cells per window of the grid the ground surface is fitted on (then interpolated back), each
a quarter of the fit's standard deviation (on the bed of ``TREND``, coarse cells of half it
found 94 %)."""

REFITS = 3
"""Times the ground found is fitted and taken again (found share on the bed of ``TREND``: 89 %,
95 %, 96 %)."""

SUPPORT = 0.05
"""Least share of the fit's neighbourhood (weighted) that is ground found for the fit to hold
there (on the bed of ``TREND``: 0, 0.05 and 0.2 found 96 %, 96 % and 92 %)."""

FOOT_CELLS = 1
"""Rim of the ground found left out of the fit [cells]: a rock's foot within the tolerance of
the ground lies there, and fitted it lifts the surface round every rock (on a test scene of domes
on a slope, rock faces up to 7 mm over the 4 cm tolerance were called ground, none with the rim
left out)."""

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


def _opening(z: F64, half: int, drop: float, outside: Mask) -> F64:
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


def ground_height(points: npt.ArrayLike, window: float, cell: float, tolerance: float) -> F64:
    """Height of the open ground under each point (see the module documentation).

    Args:
        points: Nx3 positions, z up [m].
        window: Side of the square open ground must hold, wider than the largest rock's b [m].
        cell: Grid cell seen from above [m]; about the mesh's edge length (``GRID_CELLS`` sets
            the coarsest).
        tolerance: Height over the ground under which a point is on it [m].

    Returns:
        N heights of the surface fitted to the open ground found [m]; NaN where it does not
        reach, everywhere when no patch is found or ``window`` or ``cell`` is not positive.

    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if window <= 0 or cell <= 0 or not len(p):
        return np.full(len(p), np.nan)
    cell = max(cell, window / GRID_CELLS)
    at = (p[:, :2] - p[:, :2].min(axis=0)) / cell
    ij = np.floor(at).astype(np.int64)
    shape = tuple(int(n) for n in ij.max(axis=0) + 1)
    flat = ij[:, 0] * shape[1] + ij[:, 1]
    lowest = np.full(shape[0] * shape[1], np.inf)
    np.minimum.at(lowest, flat, p[:, 2])
    low = lowest.reshape(shape)
    empty = np.isinf(low)
    distance, (ni, nj) = ndimage.distance_transform_edt(empty, return_indices=True)
    low = low[ni, nj]
    outside = distance > HOLE_CELLS
    half = round(window / (2 * cell))
    envelope = _opening(low, half, SHEET * window / 2, outside)
    near = _within(low, envelope, tolerance, outside)
    # Past the survey's edge nothing contradicts a patch.
    wide = (
        ndimage.uniform_filter(
            (near | outside).astype(np.float64), size=2 * half + 1, mode='nearest'
        )
        >= RESTING - 1e-9
    )
    found = _joining(near, wide)
    if not found.any():
        return np.full(len(p), np.nan)
    fit_cells = max(1, round(window / (FIT_CELLS * cell)))
    centres = np.indices(low.shape) + 0.5
    coarse, held = _trend(low, ndimage.binary_erosion(found, iterations=FOOT_CELLS), fit_cells)
    for _ in range(REFITS - 1):
        surface = _surface_at(coarse, held, fit_cells, centres)
        found = _joining(_within(low, surface, tolerance, outside), found)
        coarse, held = _trend(low, ndimage.binary_erosion(found, iterations=FOOT_CELLS), fit_cells)
    height = _surface_at(coarse, held, fit_cells, at.T)
    height[np.isinf(height)] = np.nan
    return height


def _within(low: F64, surface: F64, tolerance: float, outside: Mask) -> Mask:
    """Cells of the survey whose lowest point is within ``tolerance`` over ``surface``."""
    near = ~outside
    near[near] = low[near] - surface[near] <= tolerance
    return near


def _joining(near: Mask, seeds: Mask) -> Mask:
    """Cells of the connected parts of ``near`` that hold a seed."""
    parts, _ = ndimage.label(near)
    joined: Mask = np.isin(parts, np.unique(parts[seeds & (parts > 0)]))
    return joined


def _trend(low: F64, found: Mask, cells: int) -> tuple[F64, Mask]:
    """Smooth surface through the ground found: a local quadratic fit on a coarse grid.

    Args:
        low: Lowest point per cell [m].
        found: Cells of ground found.
        cells: Cells per side of a coarse cell.

    Returns:
        The surface's height per coarse cell [m], and where found ground weighs at least
        ``SUPPORT`` of the neighbourhood (elsewhere the height means nothing).

    """
    rows, cols = -(-low.shape[0] // cells), -(-low.shape[1] // cells)
    z = np.zeros((rows * cells, cols * cells))
    w = np.zeros_like(z)
    z[: low.shape[0], : low.shape[1]] = np.where(found, low, 0.0)
    w[: low.shape[0], : low.shape[1]] = found
    z = z.reshape(rows, cells, cols, cells).sum(axis=(1, 3))
    w = w.reshape(rows, cells, cols, cells).sum(axis=(1, 3))
    sigma = TREND * FIT_CELLS
    reach = int(np.ceil(3 * sigma))
    u = np.arange(-reach, reach + 1, dtype=np.float64)
    gauss = np.exp(-0.5 * (u / sigma) ** 2)

    def moment(image: F64, pu: int, pv: int) -> F64:
        along = ndimage.correlate1d(image, gauss * u**pu, axis=0, mode='constant')
        out: F64 = ndimage.correlate1d(along, gauss * u**pv, axis=1, mode='constant')
        return out

    terms = [(0, 0), (1, 0), (0, 1), (2, 0), (1, 1), (0, 2)]
    normal = np.empty((rows, cols, 6, 6))
    rhs = np.empty((rows, cols, 6))
    for i, (pu, pv) in enumerate(terms):
        rhs[..., i] = moment(z, pu, pv)
        for j, (qu, qv) in enumerate(terms[i:], start=i):
            normal[..., i, j] = normal[..., j, i] = moment(w, pu + qu, pv + qv)
    held = normal[..., 0, 0] >= SUPPORT * cells**2 * gauss.sum() ** 2
    coarse = np.zeros((rows, cols))
    coarse[held] = np.linalg.solve(normal[held], rhs[held][..., None])[:, 0, 0]
    return coarse, held


def _surface_at(coarse: F64, held: Mask, cells: int, at: F64) -> F64:
    """Sample the fitted surface at ``at`` (2 x ..., in cells); -inf where it does not reach.

    A position the fit reaches on only some sides of the coarse cells round it is past it.
    """
    where = (at - cells / 2) / cells
    height: F64 = ndimage.map_coordinates(coarse, where, order=1, mode='nearest')
    reached = ndimage.map_coordinates(held.astype(np.float64), where, order=1, mode='nearest')
    height[reached < 1 - 1e-9] = -np.inf
    return height
