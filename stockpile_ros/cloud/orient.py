"""Which side of the surface each normal of a cloud points to, without the sensor's position.

A normal estimated from the nearest points has no side. A survey sees the pile from outside, so
each normal must point to where the point was seen from. Turning every normal up (the rule before)
gets that wrong wherever the surface faces down: a tripod or a cart beside a pile sees the
undersides of rocks and overhangs. On bench/bench_cloud.py's survey (220 rocks, eight stations
1.5 m up round the pile and one above) 23 % of the true normals face down, 22 % of the normals
turned up were on the wrong side, and Poisson folded the surface there: rocks cut into pieces
(precision 0.59). Turned as here, 3.7 % were wrong (0.7 s for its 135k points) and the survey
gave precision 0.94.

The rule: the cloud is looked at along :data:`VIEWS` parallel directions (straight down, and
round it from low and high elevations) through a depth buffer of cells
:data:`PIXEL_SPACINGS` point spacings wide; a point is seen along a direction when no point in
its cell or the eight around lies more than :data:`DEPTH_SPACINGS` spacings in front of it, and
its normal is turned towards the directions it is seen along. A point seen along none (the
bottoms of the gaps between rocks) takes the side its oriented neighbours agree on, those whose
normal lies within :data:`AGREE_COS` of its own, round after round; a point that none reaches
turns up.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from scipy.spatial import cKDTree

__all__ = ['AGREE_COS', 'DEPTH_SPACINGS', 'PIXEL_SPACINGS', 'VIEWS', 'orient_outward', 'seen_along']

F64 = npt.NDArray[np.float64]
B = npt.NDArray[np.bool_]


def _views(elevations_deg: tuple[float, ...], azimuths: int) -> F64:
    rings = [
        [np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)]
        for e in np.radians(elevations_deg)
        for a in np.arange(azimuths) * (2 * np.pi / azimuths)
    ]
    return np.array([[0.0, 0.0, 1.0], *rings])


#: Directions towards the viewer: straight down on the cloud, and from eight headings at 15 and
#: 40 degrees above the horizon, as stations round a pile and a cart's camera see it. On the
#: survey above (3.7 % wrong with these), elevations 10, 25, 45 and 65 degrees left 3.5 %,
#: sixteen headings 3.5 %, 25 degrees alone 4.9 %; each view costs a sort of the points.
VIEWS: F64 = _views((15.0, 40.0), 8)
#: Depth-buffer cell [point spacings]: about one keeps nearly every cell filled by the surface in
#: front when it is seen square on; coarser cells let points hide neighbours of their own surface
#: (on the survey: 1 spacing 3.8 % wrong, 3 spacings 8.7 %).
PIXEL_SPACINGS = 1.5
#: A point counts as seen when it lies within this depth of the nearest point of its cell and the
#: eight around [point spacings]: the surface's own noise and slope across the cells (0.5: 4.1 %
#: wrong, 2: 3.5 %).
DEPTH_SPACINGS = 1.0
#: Neighbours a point unseen along every view takes its side from.
NEIGHBOURS = 10
#: Least cosine between two normals for one's side to say the other's (37 degrees): across a
#: sharper turn, as at the rim of a rock, the sign of the cosine is no guide. 0.5 left 4.2 %
#: wrong, 0 (any neighbour) 4.7 %.
AGREE_COS = 0.8


def seen_along(points: F64, direction: F64, pixel: float, depth: float) -> B:
    """Return which points are seen along ``direction`` (towards the viewer, unit length).

    A depth buffer of square cells ``pixel`` wide across the direction; a point is seen when it
    lies within ``depth`` of the nearest point in its cell and the eight around it. The buffer
    is kept sparse (sorted cell keys), so a long survey strip costs no more than its points.
    """
    helper = np.array([1.0, 0.0, 0.0]) if abs(direction[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    across = np.cross(direction, helper)
    across /= np.linalg.norm(across)
    axes = np.stack([across, np.cross(direction, across)])
    # One cell of margin on each side, so that the neighbouring keys of a cell never wrap.
    cells = np.floor((points @ axes.T) / pixel).astype(np.int64)
    cells -= cells.min(axis=0) - 1
    width = int(cells[:, 1].max()) + 2
    keys = cells[:, 0] * width + cells[:, 1]
    nearness = -(points @ direction)
    order = np.argsort(keys, kind='stable')
    unique, start, inverse = np.unique(keys[order], return_index=True, return_inverse=True)
    front = np.minimum.reduceat(nearness[order], start)
    around = front.copy()
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            if di == dj == 0:
                continue
            wanted = unique + di * width + dj
            at = np.minimum(np.searchsorted(unique, wanted), len(unique) - 1)
            found = unique[at] == wanted
            around[found] = np.minimum(around[found], front[at[found]])
    seen = np.empty(len(points), dtype=bool)
    seen[order] = nearness[order] <= around[inverse] + depth
    return seen


def orient_outward(points: F64, normals: F64, spacing: float) -> tuple[F64, float]:
    """Turn each normal to the side the cloud is seen from (see the module's rule).

    Args:
        points: Nx3 points, z up.
        normals: Nx3 unit normals of either side.
        spacing: Median distance between neighbouring points (same unit as ``points``).

    Returns:
        The normals turned, and the share of points seen along some view (the rest took their
        neighbours' side).

    """
    towards = np.zeros_like(points)
    for direction in VIEWS:
        seen = seen_along(points, direction, PIXEL_SPACINGS * spacing, DEPTH_SPACINGS * spacing)
        towards[seen] += direction
    side = np.sign(np.einsum('ij,ij->i', normals, towards))
    seen_share = float(np.mean(side != 0))
    if (side == 0).any() and len(points) > NEIGHBOURS:
        _, near = cKDTree(points).query(points, k=NEIGHBOURS + 1)
        near = near[:, 1:]
        while True:
            todo = np.flatnonzero(side == 0)
            if len(todo) == 0:
                break
            cos = np.einsum('ij,ikj->ik', normals[todo], normals[near[todo]])
            vote = np.sum(np.where(np.abs(cos) >= AGREE_COS, cos, 0.0) * side[near[todo]], axis=1)
            decided = vote != 0
            if not decided.any():
                break
            side[todo[decided]] = np.sign(vote[decided])
    side = np.where(side == 0, np.where(normals[:, 2] < 0, -1.0, 1.0), side)
    return normals * side[:, None], seen_share
