"""Which side of the surface each normal of a cloud points to, without the sensor's position.

A normal estimated from the nearest points has no side. A survey sees the pile from outside, so
each normal must point to where the point was seen from. Turning every normal up (the rule before)
gets that wrong wherever the surface faces down: a tripod or a cart beside a pile sees the
undersides of rocks and overhangs. On bench/bench_cloud.py's survey (220 rocks, eight stations
1.5 m up round the pile and one above) 23 % of the true normals face down, 22 % of the normals
turned up were on the wrong side, and Poisson folded the surface there: rocks cut into pieces
(precision 0.59). Turned as here, 3.0 % were wrong (3.7 % with the flat depth test below; 2.5 s
for its 135k points against 1.3 s) and the survey gave precision 0.93-0.95.

The rule: the cloud is looked at along :data:`VIEWS` parallel directions (straight down, and
round it from low and high elevations) through a depth buffer of cells
:data:`PIXEL_SPACINGS` point spacings wide; a point is seen along a direction when no point in
its cell or the eight around lies more than :data:`DEPTH_SPACINGS` spacings in front of the
point's own tangent plane (see :func:`seen_along`), and its normal is turned towards the
directions it is seen along. A point seen along none (the bottoms of the gaps between rocks)
takes the side its oriented neighbours agree on, those whose normal lies within
:data:`AGREE_COS` of its own, round after round; a point that none reaches turns up.

Until 2026-12-07 the depth test was flat (no point within ``DEPTH_SPACINGS`` in front of the
point itself): a surface steep to every view hid itself, so only 45-48 % of the points were
seen and the rest took their side from neighbours, wrongly for 6-7 % of them, on undersides
facing down most (their patches, turned up, Poisson drew facing into the rock: on a riprap bed
scanned at 6.9 mm 40 of 70 false rocks). With the tangent plane 54-71 % are seen and the share
wrong fell on every survey measured: 3.7 -> 3.0 % (220-rock pile), 3.8 -> 2.0 % (riprap bed,
100 rocks of b 0.3-0.8 m), 3.9 -> 3.7 % and 5.2 -> 4.6 % (gravel bars of rounded and angular
rocks), 7.9 -> 7.6 % (a bar with fines), 5.6 -> 5.1 % (the pile thinned out with range as a
scanner's is) and 4.8 -> 3.9 % (the pile swept in rows four times farther apart across).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from scipy.spatial import cKDTree

__all__ = [
    'AGREE_COS',
    'DEPTH_SPACINGS',
    'GRAZING_COS',
    'PIXEL_SPACINGS',
    'VIEWS',
    'orient_outward',
    'seen_along',
]

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
#: 220-rock survey below (3.0 % wrong with these), elevations 5, 15 and 40 degrees left 3.0 %, 10,
#: 25, 45 and 65 degrees 2.9 %, sixteen headings 3.0 %, and on the riprap bed 2.1-2.5 % against
#: 2.0 %; each view costs a sort of the points.
VIEWS: F64 = _views((15.0, 40.0), 8)
#: Depth-buffer cell [point spacings]: about one keeps nearly every cell filled by the surface in
#: front when it is seen square on; coarser cells let points hide neighbours of their own surface
#: (on the survey, with a flat depth test: 1 spacing 3.8 % wrong, 3 spacings 8.7 %).
PIXEL_SPACINGS = 1.5
#: A point counts as seen when the nearest point of its cell and of the eight around lies no more
#: than this in front of its tangent plane [point spacings]: the surface's own noise (0.5: 3.2 %
#: wrong on the 220-rock survey, 2.0 % on the riprap bed; 2: 3.0 and 2.0 %, more of those seen
#: wrong, 0.25 % and 0.52 % against 0.14 % and 0.48 %).
DEPTH_SPACINGS = 1.0
#: Least cosine between a normal and a view for the point to be seen along it (78 degrees): nearer
#: square, a few degrees of error in the normal turn its side (0.1: the same shares wrong).
GRAZING_COS = 0.2
#: Neighbours a point unseen along every view takes its side from.
NEIGHBOURS = 10
#: Least cosine between two normals for one's side to say the other's (37 degrees): across a
#: sharper turn, as at the rim of a rock, the sign of the cosine is no guide. 0.5 left 4.2 %
#: wrong, 0 (any neighbour) 4.7 %.
AGREE_COS = 0.8


def seen_along(points: F64, normals: F64, direction: F64, pixel: float, depth: float) -> B:
    """Return which points are seen along ``direction`` (towards the viewer, unit length).

    A depth buffer of square cells ``pixel`` wide across the direction holds the nearest point
    of each cell. A point is seen when the nearest point of its cell and of each of the eight
    around lies no more than ``depth`` in front of the point's own tangent plane (its normal's
    plane, which needs no side) where that plane passes the nearest point: its own surface,
    however steep to the view, does not hide it, as it would against a flat ``depth`` (on
    bench/bench_cloud.py's surveys the share of points seen rose from 45-48 % to 54-71 % and the
    share of those wrong fell or held, 0.22 -> 0.14 % on the 220-rock pile). A point whose
    normal lies within :data:`GRAZING_COS` of square to the direction is not seen along it: its
    plane says nothing of depth there, nor its normal of the side. The buffer is kept sparse
    (sorted cell keys), so a long survey strip costs no more than its points.
    """
    helper = np.array([1.0, 0.0, 0.0]) if abs(direction[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    across = np.cross(direction, helper)
    across /= np.linalg.norm(across)
    axes = np.stack([across, np.cross(direction, across)])
    image = points @ axes.T
    # One cell of margin on each side, so that the neighbouring keys of a cell never wrap.
    cells = np.floor(image / pixel).astype(np.int64)
    cells -= cells.min(axis=0) - 1
    width = int(cells[:, 1].max()) + 2
    keys = cells[:, 0] * width + cells[:, 1]
    nearness = -(points @ direction)
    # Points by cell, nearest first (each cell's first is its front); worked on in that order,
    # so that a cell's points and its neighbours' fronts lie together in memory.
    order = np.lexsort((nearness, keys))
    unique, start, cell = np.unique(keys[order], return_index=True, return_inverse=True)
    image, nearness, normals = image[order], nearness[order], normals[order]
    facing = normals @ direction
    grazing = np.abs(facing) < GRAZING_COS
    # How the tangent plane's nearness changes across the image (the normal's sign cancels).
    slope = (normals @ axes.T) / np.where(grazing, 1.0, facing)[:, None]
    front_image, front_nearness = image[start], nearness[start]
    clear = ~grazing
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            wanted = unique + di * width + dj
            at = np.minimum(np.searchsorted(unique, wanted), len(unique) - 1)
            there = unique[at] == wanted
            # Per point: the neighbouring cell's front, if that cell holds any point.
            near = at[cell]
            plane = nearness + np.einsum('ij,ij->i', slope, front_image[near] - image)
            clear &= ~there[cell] | (front_nearness[near] >= plane - depth)
    seen = np.empty(len(points), dtype=bool)
    seen[order] = clear
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
        seen = seen_along(
            points, normals, direction, PIXEL_SPACINGS * spacing, DEPTH_SPACINGS * spacing
        )
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
