"""Ground plane of the dense cloud and the similarity into the ``stockpile`` frame.

The ``stockpile`` frame has z up and the ground at z = 0.

The ground is the plane with most RANSAC inliers among a few found one after another, restricted to
planes that keep (almost) every camera on one side and whose normal roughly agrees with the
cameras' mean "up" (the image's -y axis): on a pile with ground around it that is the ground, not a
flat rock face. Its normal is turned towards the cameras and refined by least squares on the
inliers.
The origin goes on the plane below the centroid of what rises above it (the pile).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ..errors import CaptureError
from ..geometry import Similarity

__all__ = ['GroundFit', 'fit_ground', 'pile_mask', 'stockpile_transform']

F64 = npt.NDArray[np.float64]
# Points a RANSAC hypothesis is scored on: the count's relative noise stays under 1 %.
_RANSAC_SAMPLE = 20_000


@dataclass(frozen=True)
class GroundFit:
    """The ground plane in model coordinates.

    Attributes:
        plane: ``(a, b, c, d)`` with unit normal ``(a, b, c)`` towards the cameras and
            ``a x + b y + c z + d = 0`` on the ground.
        inliers: Indices of the points on the ground.
        threshold: Inlier distance used (model units).

    """

    plane: F64
    inliers: npt.NDArray[np.int64]
    threshold: float


def _refine(points: F64) -> tuple[F64, float]:
    """Least-squares plane through ``points``: unit normal and offset."""
    centroid = points.mean(axis=0)
    _, _, vt = np.linalg.svd(points - centroid, full_matrices=False)
    normal = vt[2]
    return normal, float(-normal @ centroid)


def fit_ground(
    points: F64,
    camera_centres: F64,
    camera_ups: F64 | None = None,
    threshold: float = 0.0,
    candidates: int = 4,
    seed: int = 0,
    min_share: float = 0.1,
) -> GroundFit:
    """Find the ground plane.

    Args:
        points: Nx3 dense points (model units).
        camera_centres: Mx3 camera centres (model units).
        camera_ups: Mx3 unit "up" vectors of the cameras (-y of the optical frame) or None.
        threshold: RANSAC inlier distance; 0 picks 1 % of the cloud's extent.
        candidates: Planes extracted one after another before choosing.
        seed: RANSAC seed.
        min_share: Fewest points on the ground, as a share of all points.

    Raises:
        CaptureError: No plane big enough has the cameras on one side.

    """
    extent = float(np.linalg.norm(np.percentile(points, 95, axis=0) - np.percentile(points, 5, 0)))
    if threshold <= 0:
        threshold = 0.01 * extent
    up = None
    if camera_ups is not None and len(camera_ups):
        mean_up = camera_ups.mean(axis=0)
        if np.linalg.norm(mean_up) > 0.3:
            up = mean_up / np.linalg.norm(mean_up)
    rng = np.random.default_rng(seed)
    remaining = np.arange(len(points))
    best: tuple[int, F64, npt.NDArray[np.int64]] | None = None
    for _ in range(candidates):
        if len(remaining) < 100:
            break
        inl = remaining[_ransac_plane(points[remaining], threshold, rng)]
        remaining = np.setdiff1d(remaining, inl)
        normal, offset = _refine(points[inl])
        side = camera_centres @ normal + offset
        if np.median(side) < 0:
            normal, offset, side = -normal, -offset, -side
        if np.mean(side > 0) < 0.9 or len(inl) < min_share * len(points):
            continue
        if up is not None and normal @ up < 0.5:
            continue
        if best is None or len(inl) > best[0]:
            best = (len(inl), np.append(normal, offset), inl)
    if best is None:
        raise CaptureError(
            'mesh',
            'no ground plane was found below the cameras',
            'Keep some ground around the pile in view, and hold the camera upright',
        )
    plane = best[1]
    # Final inliers against the refined plane.
    inliers = np.nonzero(np.abs(points @ plane[:3] + plane[3]) < threshold)[0]
    normal, offset = _refine(points[inliers])
    if normal @ plane[:3] < 0:
        normal, offset = -normal, -offset
    return GroundFit(np.append(normal, offset), inliers.astype(np.int64), threshold)


def _ransac_plane(
    points: F64, threshold: float, rng: np.random.Generator, iterations: int = 1000
) -> npt.NDArray[np.int64]:
    """Return the points within ``threshold`` of the plane through three points most lie near.

    Hypotheses are scored on a fixed sample of the points; the same seed gives the same plane on
    every run (open3d's ``segment_plane`` scores them on parallel threads, and two replays of one
    bag found ground planes a few micro-radians apart).
    """
    sample = points[rng.choice(len(points), min(len(points), _RANSAC_SAMPLE), replace=False)]
    triples = points[rng.integers(0, len(points), (iterations, 3))]
    normals = np.cross(triples[:, 1] - triples[:, 0], triples[:, 2] - triples[:, 0])
    length = np.linalg.norm(normals, axis=1)
    good = length > 0
    normals, triples = normals[good] / length[good, None], triples[good]
    offsets = -np.einsum('ij,ij->i', normals, triples[:, 0])
    counts = np.concatenate(
        [
            np.count_nonzero(np.abs(sample @ n.T + o) < threshold, axis=0)
            for n, o in zip(np.array_split(normals, 10), np.array_split(offsets, 10), strict=True)
        ]
    )
    best = int(np.argmax(counts))
    return np.nonzero(np.abs(points @ normals[best] + offsets[best]) < threshold)[0]


def pile_mask(heights: F64) -> npt.NDArray[np.bool_]:
    """Points of the pile: higher than a tenth of the (nearly) highest point above the ground.

    Relative to the pile's own height, so it does not depend on the cloud's units, extent or
    noise.
    """
    return np.asarray(heights > 0.1 * float(np.percentile(heights, 99.5)))


def stockpile_transform(
    ground: GroundFit, points: F64, camera_centres: F64, metres_per_unit: float
) -> Similarity:
    """Similarity from model coordinates to the ``stockpile`` frame.

    z is the ground normal, x the horizontal direction from the pile towards the first camera
    (any fixed choice would do; this one makes the frame repeatable), the origin is on the ground
    below the centroid of the pile (:func:`pile_mask`).
    """
    normal, offset = ground.plane[:3], float(ground.plane[3])
    height = points @ normal + offset
    above = points[pile_mask(height)]
    centre = above.mean(axis=0) if len(above) else points.mean(axis=0)
    origin = centre - (centre @ normal + offset) * normal
    towards = camera_centres[0] - origin
    x_axis = towards - (towards @ normal) * normal
    if np.linalg.norm(x_axis) < 1e-9:
        x_axis = np.cross(normal, [1.0, 0.0, 0.0])
        if np.linalg.norm(x_axis) < 1e-9:
            x_axis = np.cross(normal, [0.0, 1.0, 0.0])
    x_axis /= np.linalg.norm(x_axis)
    y_axis = np.cross(normal, x_axis)
    rotation = np.stack([x_axis, y_axis, normal])
    return Similarity(metres_per_unit, rotation, -metres_per_unit * rotation @ origin)
