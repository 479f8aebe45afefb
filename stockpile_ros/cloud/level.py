"""Which way is up in a cloud, and the similarity that levels it into the ``stockpile`` frame.

Up is given (``cloud.up``) or the normal of the cloud's trend plane: a robust least-squares plane
over every point (Tukey's biweight, its scale from the quarter of the surface nearest the plane,
iteratively reweighted from the planes through three points that have the least quarter
residuals, the plane the surface hugs most tightly kept), so that on a pile with ground around it
the ground wins and on a grain-covered bar, which has no bare ground, the bar's trend does. Each
point weighs as the plan, on the plane, of the surface it stands for (the square of the distance
to its 16th nearest point times the cosine of its normal with the plane's): it is the trend of
the surface, not of the points, and a scanner samples the faces turned to it, and the rows it
sweeps, more densely than others. No single patch of ground is looked for. The plane's sign: the
side most given normals point to; else the side to which the surface rises clear of the plane,
where it does to one side only (ground is seen from above, the pile on it); else the side the
surface bulges towards over most of its area (rocks are convex and the valleys between them
narrow; a tool's frame may have any axis up, as Structure-from-Motion ones do); else the input's
+z.
z = 0 is the plane moved down to a low percentile of the heights: the ground where some shows,
the bottom of the gaps between grains where none does, so that the surface lies above it.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from scipy.spatial import cKDTree

from ..errors import StockpileError
from ..geometry import Similarity
from ..recon.ground import pile_mask
from .noise import neighbourhoods

__all__ = ['SIGN_FROM_INPUT_Z', 'level_transform', 'parse_up', 'trend_up']

F64 = npt.NDArray[np.float64]

#: How :func:`trend_up` says that neither the normals nor the surface told it which side is up.
SIGN_FROM_INPUT_Z = "the input's +z (no side rises or bulges clearly)"

# Tukey's biweight constant (95 % efficiency under Gaussian residuals).
_TUKEY = 4.685
# The residuals' spread is taken from the points nearest the plane: the standard deviation of a
# Gaussian is its absolute values' 25th percentile over 0.3186. The median (the MAD) would need
# half the points on the plane; a survey of a pile has more of them on the pile than on the ground.
_QUANTILE = 25.0
_QUANTILE_SIGMA = 1.0 / 0.3186
_ITERATIONS = 30
# Random triples the start is chosen among, and the points their residuals are taken over: with a
# quarter of the points on the ground, 1000 triples miss an all-ground one with odds
# (63/64)^1000, about 1e-7.
_TRIPLES = 1000
_START_SAMPLE = 2000
# Starts the biweight is refined from: the triples of least quarter-plan residual.
_STARTS = 8
# More points than this add nothing to a plane's three parameters but time.
_PLANE_SAMPLE = 50_000
# How far from half the share of bulging points must be to tell the sides apart, and the points
# (sampled) and neighbourhoods (points) that share is taken over.
_CONVEX_MARGIN = 0.05
_CONVEX_SAMPLE = 20_000
_CONVEX_NEIGHBOURS = 50
_FLAT = 1e-9
# Ground is seen from above: where the surface hugs the plane and a share of it of at least
# _RISE_SHARE rises more than _RISE_SPREADS spreads to one side, with at most _RISE_OTHER times as
# much to the other, that side is up (a pile or a bed within its ground). A bed with no bare
# ground has the plane through its grains' tops and narrow gaps under it: no side is clear.
_RISE_SPREADS = 3.0
_RISE_SHARE = 0.1
_RISE_OTHER = 0.1
# Points whose distances give the surface each point stands for, and the most it may weigh, in
# medians (a stray point far from the rest stands for no surface).
_AREA_NEIGHBOURS = 16
_AREA_MAX = 10.0


def parse_up(text: str) -> F64 | None:
    """Return the unit up vector of ``x,y,z`` text, or None for ``fit`` (the trend plane).

    Raises:
        StockpileError: Not ``fit`` nor three finite numbers of non-zero length.

    """
    if text.strip().lower() == 'fit':
        return None
    try:
        values = np.array([float(v) for v in text.split(',')], dtype=np.float64)
    except ValueError:
        values = np.zeros(0)
    norm = float(np.linalg.norm(values)) if values.size == 3 else 0.0
    if values.size != 3 or not np.isfinite(values).all() or norm == 0:
        raise StockpileError(f'up {text!r}: expected "fit" or three numbers x,y,z (e.g. 0,0,1)')
    return np.asarray(values / norm)


def _plane(points: F64, weights: F64) -> tuple[F64, F64]:
    centre = np.average(points, axis=0, weights=weights)
    d = points - centre
    cov = (d * weights[:, None]).T @ d / weights.sum()
    _, vectors = np.linalg.eigh(cov)
    return np.asarray(vectors[:, 0]), np.asarray(centre)


def _quarter(sizes: F64, weights: F64) -> F64:
    """Return, per column, the size under which a quarter of the column's weight lies."""
    order = np.argsort(sizes, axis=0)
    cumulative = np.cumsum(np.take_along_axis(weights, order, axis=0), axis=0)
    at = np.argmax(cumulative >= _QUANTILE / 100.0 * cumulative[-1], axis=0)
    return np.asarray(np.take_along_axis(sizes, order, axis=0)[at, np.arange(sizes.shape[1])])


def _spread(residuals: F64, area: F64) -> float:
    """Return the standard deviation of the residuals of the surface nearest the plane."""
    return _QUANTILE_SIGMA * float(_quarter(np.abs(residuals)[:, None], area[:, None])[0])


def _surface(points: F64) -> tuple[F64, F64]:
    """Return the surface each point stands for (in medians) and its unit normal (either way).

    The area is the square of the distance to the point's 16th nearest (the inverse of the
    density), the normal that of the plane through those points.
    """
    k = min(len(points) - 1, _AREA_NEIGHBOURS)
    if k < 3:
        return np.ones(len(points)), np.tile([0.0, 0.0, 1.0], (len(points), 1))
    distance, _, axes = neighbourhoods(points, points, k + 1)
    area = distance[:, -1] ** 2
    typical = float(np.median(area))
    area = np.minimum(area / typical, _AREA_MAX) if typical > 0 else np.ones(len(points))
    return np.asarray(area), np.asarray(axes[:, :, 0])


def _start_planes(
    points: F64, area: F64, facing: F64, rng: np.random.Generator
) -> list[tuple[F64, F64]]:
    """Return the planes through three of ``points`` whose quarter-plan residuals are least.

    Each residual weighs as its point's plan on the plane (see :func:`_refine`), so that a
    plane through ground is judged by the ground, not by faces the scanner saw densely.
    """
    pick = rng.choice(len(points), min(len(points), _START_SAMPLE), replace=False)
    sample, weight, seen = points[pick], area[pick], facing[pick]
    tri = sample[rng.integers(0, len(sample), (_TRIPLES, 3))]
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    length = np.linalg.norm(normals, axis=1)
    ok = length > 0
    if not ok.any():
        return [_plane(points, np.ones(len(points)))]
    normals, tri = normals[ok] / length[ok, None], tri[ok]
    offsets = np.einsum('ij,ij->i', normals, tri[:, 0])
    residual = np.abs(sample @ normals.T - offsets)
    spread = _quarter(residual, weight[:, None] * np.abs(seen @ normals.T))
    return [(np.asarray(normals[k]), np.asarray(tri[k, 0])) for k in np.argsort(spread)[:_STARTS]]


def _refine(
    sample: F64, area: F64, normals: F64, normal: F64, centre: F64
) -> tuple[F64, F64, float]:
    """Return the biweight plane reached from a start (normal, a point) and its residuals' spread.

    Each point weighs as the plan of its surface on the plane: its area times the cosine of
    its normal with the plane's.
    """
    plan = area * np.abs(normals @ normal)
    spread = _spread((sample - centre) @ normal, plan)
    for _ in range(_ITERATIONS):
        if spread == 0:
            break
        u = (sample - centre) @ normal / (_TUKEY * spread)
        weights = np.where(np.abs(u) < 1, (1 - u**2) ** 2, 0.0) * plan
        if np.count_nonzero(weights) < 3:
            break
        previous = normal
        normal, centre = _plane(sample, weights)
        plan = area * np.abs(normals @ normal)
        spread = _spread((sample - centre) @ normal, plan)
        if abs(float(previous @ normal)) > 1 - 1e-12:
            break
    return normal, centre, spread


def _rising_side(residuals: F64, plan: F64, spread: float) -> int:
    """Return +1 or -1 where the surface rises clear of the plane to one side only, else 0."""
    total = float(plan.sum())
    if spread <= 0 or total <= 0:
        return 0
    above = float(plan[residuals > _RISE_SPREADS * spread].sum()) / total
    below = float(plan[residuals < -_RISE_SPREADS * spread].sum()) / total
    high, low = max(above, below), min(above, below)
    if high < _RISE_SHARE or low > _RISE_OTHER * high:
        return 0
    return 1 if above > below else -1


def trend_up(points: F64, normals: F64 | None = None, seed: int = 0) -> tuple[F64, str]:
    """Return the unit normal of the robust trend plane, turned up, and how its sign was chosen."""
    rng = np.random.default_rng(seed)
    sample = points if len(points) <= _PLANE_SAMPLE else points[
        rng.choice(len(points), _PLANE_SAMPLE, replace=False)]  # fmt: skip
    area, facing = _surface(sample - sample.mean(axis=0))
    # Refined from several starts, the plane the surface hugs most tightly: a pile over ground has
    # more than one plane a biweight settles on (one leaning on the pile's foot), ground the
    # tightest of them.
    starts = _start_planes(sample, area, facing, rng)
    fits = [_refine(sample, area, facing, n, c) for n, c in starts]
    normal, centre, spread = min(fits, key=lambda fit: fit[2])
    if normals is not None:
        side = float(np.mean(normals @ normal > 0))
        if side != 0.5:
            return (normal if side > 0.5 else -normal), 'the side most given normals face'
    rising = _rising_side((sample - centre) @ normal, area * np.abs(facing @ normal), spread)
    if rising:
        return rising * normal, 'the side the surface rises to from the plane it hugs'
    bulging = _bulging_share(points, normal, rng)
    if abs(bulging - 0.5) >= _CONVEX_MARGIN:
        return (normal if bulging > 0.5 else -normal), 'the side the surface bulges towards'
    return (normal if normal[2] >= 0 else -normal), SIGN_FROM_INPUT_Z


def _bulging_share(points: F64, normal: F64, rng: np.random.Generator) -> float:
    """Share of points higher along ``normal`` than the mean of their nearest points.

    Rocks are convex: over most of a pile's or a bed's surface it bends away from the side it is
    seen from, and the valleys between them are narrow.
    """
    picks = rng.choice(len(points), min(len(points), _CONVEX_SAMPLE), replace=False)
    heights = (points - points.mean(axis=0)) @ normal
    _, near = cKDTree(points).query(points[picks], k=min(len(points), _CONVEX_NEIGHBOURS))
    bulge = heights[picks] - heights[near].mean(axis=1)
    # Flat parts (within rounding of the cloud's size) bend neither way: they do not vote.
    flat = np.abs(bulge) <= _FLAT * float(np.ptp(heights))
    votes = bulge[~flat]
    return float(np.mean(votes > 0)) if len(votes) else 0.5


def level_transform(
    points: F64, up: F64, metres_per_unit: float, ground_percentile: float
) -> tuple[Similarity, F64]:
    """Similarity from the input frame into the ``stockpile`` frame, and the ground plane.

    z is ``up``; x the input's x (else y) laid in the plane, so a survey keeps its heading; the
    origin is on the ground (``ground_percentile`` of the heights along ``up``) below the centroid
    of what rises above it (:func:`~stockpile_ros.recon.ground.pile_mask`).

    Returns:
        The similarity and the ground plane ``(a, b, c, d)`` in input coordinates.

    """
    centre = points.mean(axis=0)
    heights = (points - centre) @ up
    floor = float(np.percentile(heights, ground_percentile))
    above = points[pile_mask(heights - floor)]
    middle = above.mean(axis=0) if len(above) else centre
    origin = middle - ((middle - centre) @ up - floor) * up
    x_axis = np.array([1.0, 0.0, 0.0]) - up[0] * up
    if np.linalg.norm(x_axis) < 1e-6:
        x_axis = np.array([0.0, 1.0, 0.0]) - up[1] * up
    x_axis /= np.linalg.norm(x_axis)
    rotation = np.stack([x_axis, np.cross(up, x_axis), up])
    sim = Similarity(metres_per_unit, rotation, -metres_per_unit * rotation @ origin)
    return sim, np.append(up, -float(up @ origin))
