"""A self-calibrated camera's focal length from the printed targets it saw.

Structure-from-Motion refines a phone's focal length from the scene alone, and a focal length
off by some share scales the model against the camera path by about as much: on simulated walks
round a pile with one marker the refined focal length was 0.2-1.6 % off (EXIF only starts it),
and the marker's scale with it. The marker itself is a plane of known shape seen from many
sides, which is how cameras are calibrated (Zhang's method): the homographies of its views pin
the focal length and the first radial distortion term, with the principal point held where
the model has it. On the same walks that focal length was within 0.25 % of the truth, whatever
the distortion it started from (held at the model's refined distortion instead, it was off by
0.1-1.4 %: a wrong distortion is taken up by the focal length). Its uncertainty is the
leave-one-view-out jackknife spread, which does not assume the corner errors independent.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
import numpy.typing as npt

from ..camera import CameraModel
from .scale import MarkerDetections, MarkerSpec, Target, TargetSpec, detect_charuco

__all__ = ['MIN_VIEWS', 'TargetFocal', 'planar_views', 'target_focal']

F64 = npt.NDArray[np.float64]

#: Fewest views of a target plane for its focal length to count.
MIN_VIEWS = 6

#: Largest jackknife uncertainty of the focal length that is used.
MAX_REL_UNCERTAINTY = 0.01

#: Least median tilt of the target planes against the optical axes [deg]: seen face on, a plane's
#: homography does not tell the focal length from the distance (the calibration would return its
#: starting guess with no spread at all).
MIN_TILT_DEG = 20.0

#: Fewest ChArUco corners a view of a board needs.
_MIN_BOARD_CORNERS = 6


@dataclass(frozen=True)
class TargetFocal:
    """A focal length measured on the targets' views.

    Attributes:
        focal_px: The focal length [px].
        k1: The first radial distortion term (OpenCV's, which is COLMAP's ``SIMPLE_RADIAL`` k).
        rel_uncertainty: Leave-one-view-out jackknife standard deviation over ``focal_px``.
        views: Target views it rests on (a marker or a board in one keyframe).
        rms_px: Reprojection error of the target corners [px].

    """

    focal_px: float
    k1: float
    rel_uncertainty: float
    views: int
    rms_px: float


PlanarView = tuple[F64, F64]
"""A target plane in one image: Nx3 corner positions on the target [m] (z = 0), Nx2 pixels."""


def planar_views(
    image: npt.NDArray[np.uint8], markers: MarkerDetections, targets: Sequence[Target]
) -> list[PlanarView]:
    """Every target plane of one keyframe with its corners: the markers given a size, the boards.

    Args:
        image: The keyframe (RGB).
        markers: Its marker detections (:func:`.scale.detect_markers`).
        targets: The targets of ``recon.target``.

    """
    out: list[PlanarView] = []
    for spec in targets:
        if isinstance(spec, MarkerSpec):
            s = spec.size
            square = np.array([[0, 0, 0], [s, 0, 0], [s, s, 0], [0, s, 0]], dtype=np.float64)
            for (dictionary, marker_id), quad in markers.items():
                if dictionary == spec.dictionary and spec.marker_id in (None, marker_id):
                    out.append((square, np.asarray(quad, dtype=np.float64)))
        elif isinstance(spec, TargetSpec):
            ids, px = detect_charuco(image, spec)
            if len(ids) >= _MIN_BOARD_CORNERS:
                out.append((spec.corners()[ids], px))
    return out


def _calibrate(
    views: Sequence[PlanarView], camera: CameraModel
) -> tuple[float, float, float, float] | None:
    """Focal length, k1, RMS error [px] and median plane tilt [deg]; principal point held."""
    flags = (
        cv2.CALIB_USE_INTRINSIC_GUESS
        | cv2.CALIB_FIX_PRINCIPAL_POINT
        | cv2.CALIB_FIX_ASPECT_RATIO
        | cv2.CALIB_ZERO_TANGENT_DIST
        | cv2.CALIB_FIX_K2
        | cv2.CALIB_FIX_K3
    )
    dist = np.zeros(5)
    dist[0] = camera.d[0] if len(camera.d) else 0.0
    k = np.array(camera.k, dtype=np.float64)
    try:
        rms, k_out, d_out, rvecs, _ = cv2.calibrateCamera(
            [o.astype(np.float32) for o, _ in views],
            [p.astype(np.float32).reshape(-1, 1, 2) for _, p in views],
            (camera.width, camera.height),
            k,
            dist,
            flags=flags,
        )
    except cv2.error:
        return None
    focal, k1 = float(k_out[0, 0]), float(np.ravel(d_out)[0])
    if not (math.isfinite(focal) and focal > 0 and math.isfinite(k1)):
        return None
    normals_z = [abs(float(cv2.Rodrigues(r)[0][2, 2])) for r in rvecs]
    tilt = math.degrees(math.acos(min(1.0, float(np.median(normals_z)))))
    return focal, k1, float(rms), tilt


def target_focal(views: Sequence[PlanarView], camera: CameraModel) -> TargetFocal | None:
    """Return the focal length the target planes give, or None when they cannot pin it.

    Args:
        views: Target planes of the keyframes of one camera (:func:`planar_views`).
        camera: That camera as the model has it (its principal point is held, its focal length
            and k1 are where the calibration starts).

    Returns:
        The focal length and its jackknife uncertainty; None for fewer than ``MIN_VIEWS``
        views, a failed calibration, planes seen nearly face on (a median tilt under
        ``MIN_TILT_DEG``) or an uncertainty above ``MAX_REL_UNCERTAINTY``.

    """
    if len(views) < MIN_VIEWS:
        return None
    full = _calibrate(views, camera)
    if full is None:
        return None
    focal, k1, rms, tilt = full
    if tilt < MIN_TILT_DEG:
        return None
    left_out = [_calibrate([v for k, v in enumerate(views) if k != i], camera)
                for i in range(len(views))]  # fmt: skip
    values = np.array([x[0] for x in left_out if x is not None], dtype=np.float64)
    if len(values) < len(views) - 1:
        return None
    n = len(values)
    spread = math.sqrt((n - 1) / n * float(np.sum((values - values.mean()) ** 2))) / focal
    if spread > MAX_REL_UNCERTAINTY:
        return None
    return TargetFocal(focal, k1, spread, len(views), rms)
