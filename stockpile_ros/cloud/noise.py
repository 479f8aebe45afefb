"""How far a cloud's points scatter about the surface they sample: its noise.

A scanner's range noise, a phone's depth noise, the spread of another tool's dense points: where
it is comparable with the point spacing, a surface meshed at the spacing draws the noise as
bumps and creases, and the search cuts rocks along them. The noise is measured where the surface
is smooth: each sampled point's nearest points are fitted with a quadric over their own tangent
plane (a rock's curvature is taken out with it), and the residuals' spread is read off the
smoothest quarter of the fits, since fits across a rock's edge or a crevice between rocks spread
more for the shape's sake, not the noise's.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from scipy.spatial import cKDTree
from scipy.stats import chi2

__all__ = ['neighbourhoods', 'point_noise']

F64 = npt.NDArray[np.float64]

# Quadric over the tangent plane: z = a x^2 + b xy + c y^2 + d x + e y + f.
_TERMS = 6
# The share of the fits read: the smoothest quarter.
_QUANTILE = 0.25


def neighbourhoods(points: F64, at: F64, k: int) -> tuple[F64, F64, F64]:
    """Return the ``k`` points nearest each of ``at``, centred, and their principal axes.

    Returns:
        Distances to them (n x k, nearest first), their offsets from their mean (n x k x 3) and
        the axes of those offsets (n x 3 x 3, columns by increasing spread: the first is the
        normal of the plane through them).

    """
    distance, near = cKDTree(points).query(at, k=k)
    local = points[near] - points[near].mean(axis=1, keepdims=True)
    _, axes = np.linalg.eigh(np.einsum('nki,nkj->nij', local, local))
    return np.asarray(distance, dtype=np.float64), local, np.asarray(axes)


def point_noise(points: F64, neighbours: int = 20, sample: int = 20_000, seed: int = 0) -> float:
    """Return the standard deviation of the points about their surface along its normal.

    Args:
        points: Nx3 points.
        neighbours: Points in each quadric fit (the point and its nearest).
        sample: Most points whose neighbourhoods are fitted (an even random draw beyond it).
        seed: Seed of that draw.

    Returns:
        The lower quartile of the fits' residual standard deviations, divided by the quartile a
        pure Gaussian noise gives (so that it estimates that noise's standard deviation); 0 when
        there are too few points for one fit [units of the points].

    """
    pts = np.asarray(points, dtype=np.float64)
    if len(pts) < max(neighbours, _TERMS + 1):
        return 0.0
    # Centred: survey coordinates far from the origin would lose the noise in rounding.
    pts = pts - pts.mean(axis=0)
    rng = np.random.default_rng(seed)
    at = rng.choice(len(pts), sample, replace=False) if len(pts) > sample else np.arange(len(pts))
    _, local, axes = neighbourhoods(pts, pts[at], neighbours)
    # Eigenvalues ascending: the first axis is the normal, the other two span the tangent plane.
    frame = np.einsum('nki,nij->nkj', local, axes)
    z, x, y = frame[..., 0], frame[..., 1], frame[..., 2]
    terms = np.stack([x * x, x * y, y * y, x, y, np.ones_like(x)], axis=-1)
    normal = np.einsum('nki,nkj->nij', terms, terms)
    rhs = np.einsum('nki,nk->ni', terms, z)[..., None]
    # A degenerate neighbourhood (points on a line, repeated points) has no quadric: left out.
    ok = np.linalg.cond(normal) < 1e12
    if not ok.any():
        return 0.0
    coef = np.linalg.solve(normal[ok], rhs[ok])[..., 0]
    residual = z[ok] - np.einsum('nki,ni->nk', terms[ok], coef)
    dof = neighbours - _TERMS
    spread = np.sqrt(np.sum(residual * residual, axis=1) / dof)
    # The quartile of sqrt(chi2(dof) / dof): what the lower quartile of pure noise's spreads is.
    gaussian = float(np.sqrt(chi2.ppf(_QUANTILE, dof) / dof))
    return float(np.quantile(spread, _QUANTILE) / gaussian)
