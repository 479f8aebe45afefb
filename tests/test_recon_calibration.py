"""The focal length from a printed target's views (Zhang's planar calibration)."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from stockpile_ros.camera import CameraModel
from stockpile_ros.recon.calibration import MIN_VIEWS, target_focal

TRUE = CameraModel.from_fov(640, 480, 60.0)
SIZE = 0.25
SQUARE = np.array([[0, 0, 0], [SIZE, 0, 0], [SIZE, SIZE, 0], [0, SIZE, 0]], dtype=np.float64)


def _views(tilts_deg: list[float], noise_px: float = 0.02) -> list[tuple[np.ndarray, np.ndarray]]:
    """The square seen from 2.5 m at each tilt, turned and moved about the view, jittered."""
    rng = np.random.default_rng(1)
    out = []
    for k, tilt in enumerate(tilts_deg):
        rot = Rotation.from_euler('zx', [37.0 * k, tilt], degrees=True).as_matrix()
        centre = SQUARE.mean(axis=0)
        # Across the image, as a walk puts the marker: k1 shows only away from the centre.
        cam = (SQUARE - centre) @ rot.T + [0.8 * np.sin(1.3 * k), 0.6 * np.cos(1.7 * k), 2.5]
        px = cam[:, :2] / cam[:, 2:] * TRUE.fx + [TRUE.k[0, 2], TRUE.k[1, 2]]
        out.append((SQUARE, px + rng.normal(scale=noise_px, size=px.shape)))
    return out


def _start(focal_share: float, k1: float) -> CameraModel:
    k = TRUE.k.copy()
    k[0, 0] = k[1, 1] = TRUE.fx * focal_share
    return CameraModel(TRUE.width, TRUE.height, k, np.array([k1, 0.0, 0.0, 0.0, 0.0]))


def test_oblique_views_give_the_focal_length_whatever_the_start() -> None:
    views = _views([50, 55, 60, 45, 65, 50, 58, 62])
    for start in (_start(1.02, 0.0), _start(0.985, 0.015), _start(1.0, -0.02)):
        found = target_focal(views, start)
        assert found is not None
        assert abs(found.focal_px / TRUE.fx - 1) < 0.003, found
        assert abs(found.k1) < 0.01 and found.views == len(views)
        # The jackknife spread is of the order of the error, not zero.
        assert 0 < found.rel_uncertainty < 0.01


def test_too_few_or_face_on_views_give_nothing() -> None:
    assert target_focal(_views([50] * (MIN_VIEWS - 1)), _start(1.02, 0.0)) is None
    assert target_focal(_views([3, 5, 2, 4, 6, 1, 3, 5]), _start(1.02, 0.0)) is None
