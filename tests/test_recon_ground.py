from __future__ import annotations

import numpy as np
import pytest

from stockpile_ros.errors import CaptureError
from stockpile_ros.geometry import Similarity
from stockpile_ros.recon.ground import fit_ground, stockpile_transform


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] *= -1
    return q


def _scene(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Ground disc (radius 3) with a pile (radius 1, height 0.8) at (0.5, -0.3); cameras above."""
    xy = rng.uniform(-3, 3, (20000, 2))
    ground = np.column_stack([xy, rng.normal(0, 0.003, len(xy))])
    r = np.linalg.norm(xy - [0.5, -0.3], axis=1)
    pile = ground[r < 1].copy()
    pile[:, 2] = 0.8 * (1 - r[r < 1] ** 2)
    points = np.vstack([ground[r >= 1], pile])
    angles = np.linspace(0, np.pi, 12)
    cams = np.column_stack([3 * np.cos(angles), 3 * np.sin(angles), np.full(12, 1.5)])
    return points, cams


def test_ground_found_and_frame_is_z_up_origin_under_pile() -> None:
    rng = np.random.default_rng(0)
    points, cams = _scene(rng)
    # Put the scene in arbitrary "model" coordinates: rotated, scaled by 1/2.5, shifted.
    rot = _random_rotation(rng)
    to_model = Similarity(1 / 2.5, rot, np.array([4.0, -2.0, 7.0]))
    mp, mc = to_model.apply(points), to_model.apply(cams)
    ups = np.tile(rot @ [0.0, 0.0, 1.0], (len(mc), 1))
    ground = fit_ground(mp, mc, ups)
    np.testing.assert_allclose(ground.plane[:3], rot @ [0, 0, 1], atol=2e-3)
    sim = stockpile_transform(ground, mp, mc, metres_per_unit=2.5)
    out = sim.apply(mp)
    on_ground = out[np.abs(points[:, 2]) < 0.01]
    assert np.median(np.abs(on_ground[:, 2])) < 0.005
    assert out[:, 2].max() == pytest.approx(0.8, abs=0.02)
    # The origin is under the pile: the pile's top is near z axis.
    top = out[np.argmax(out[:, 2])]
    assert np.linalg.norm(top[:2]) < 0.15
    assert np.all(sim.apply(mc)[:, 2] > 1.4)


def test_no_ground_below_cameras_fails_clearly() -> None:
    rng = np.random.default_rng(1)
    points, cams = _scene(rng)
    # Cameras on both sides of every plane: half of them below the ground.
    cams[::2, 2] = -1.5
    with pytest.raises(CaptureError, match='no ground plane'):
        fit_ground(points, cams, None)
