"""Open ground off the plane: bare patches wider than the largest rock, at any height."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pytest
from segment_fixtures import boulders_on

from stockpile_ros.artefacts import MeshInfo, ScaleRecord
from stockpile_ros.segment.ground import ground_height
from stockpile_ros.segment.params import SegmentParams
from stockpile_ros.segment.pipeline import analyse_mesh

F64 = npt.NDArray[np.float64]
RADIUS = 0.15


def _scene() -> tuple[F64, npt.NDArray[np.bool_]]:
    """Domes of b 0.3 m on ground rising 0.6 m across 4 m, sampled about every 1.5 cm."""
    rng = np.random.default_rng(0)
    x, y = (g.ravel() for g in np.meshgrid(np.arange(0, 4, 0.015), np.arange(0, 4, 0.015)))
    x, y = x + rng.uniform(0, 0.01, x.size), y + rng.uniform(0, 0.01, y.size)
    ground = 0.3 * np.sin(x / 1.5)
    z = ground.copy()
    for cx, cy in rng.uniform(0.3, 3.7, (15, 2)):
        r2 = (x - cx) ** 2 + (y - cy) ** 2
        z = np.maximum(z, ground + np.sqrt(np.clip(RADIUS**2 - r2, 0, None)))
    rock = z - ground > 0.04
    return np.stack([x, y, z], axis=1), rock


def _on_ground(points: F64, window: float) -> npt.NDArray[np.bool_]:
    height = ground_height(points, window, 0.02, 0.04)
    on: npt.NDArray[np.bool_] = points[:, 2] - height < 0.04  # NaN: not open ground
    return on


def test_open_ground_follows_the_site_and_leaves_rocks_out() -> None:
    points, rock = _scene()
    found = _on_ground(points, 0.4)
    assert found[~rock].mean() > 0.95
    assert found[rock].mean() < 0.01
    # The surface is the site's, under the rocks too.
    height = ground_height(points, 0.4, 0.02, 0.04)
    assert np.abs(height - 0.3 * np.sin(points[:, 0] / 1.5)).max() < 0.01
    # No bare patch of the 4 m survey holds a square wider than it.
    assert np.isnan(ground_height(points, 4.5, 0.02, 0.04)).all()
    assert np.isnan(ground_height(points, 0.0, 0.02, 0.04)).all()


def test_a_rock_at_the_edge_of_the_survey_is_not_ground() -> None:
    points, rock = _scene()
    # Cut the survey to a disc: squares hanging out over its edge would rest on rocks there.
    kept = np.hypot(points[:, 0] - 2, points[:, 1] - 2) < 1.9
    found = _on_ground(points[kept], 0.4)
    assert found[rock[kept]].mean() < 0.01
    assert found[~rock[kept]].mean() > 0.9


CENTRES = [(x, y) for x in (-0.6, 0.6) for y in (-0.6, 0.6)]
BOULDER_VOLUME = 2 / 3 * np.pi * 0.2**2 * 0.14  # half ellipsoids of radius 0.2 m, 0.14 m high


def _boulders(amplitude: float, offset: float) -> tuple[F64, npt.NDArray[np.int64]]:
    """Four boulders of b 0.4 m on ground waving with a 4 m period."""

    def ground(x: F64, y: F64) -> F64:
        wave = np.sin(2 * np.pi * x / 4.0) * np.cos(2 * np.pi * y / 4.0)
        return np.asarray(amplitude * (wave + offset))

    return boulders_on(ground, CENTRES)


INFO = MeshInfo(ScaleRecord('given', 1.0), units='m')


def test_ground_off_the_plane_is_left_out_when_the_largest_rock_is_known() -> None:
    # Ground rising 12 cm from z = 0: off it by more than the ground tolerance (2 edges,
    # 2.8 cm), so without a largest rock it is searched.
    v, f = _boulders(0.06, 1.0)
    plane = analyse_mesh(v, f, mesh_info=INFO)
    # The ground, as a sheet, and what would find it.
    assert any('2.79 x 2.79 m' in w and 'segment.max_rock_b' in w for w in plane.report.warnings)
    assert plane.segmentation.scale.max_rock_b == 0.0
    known = analyse_mesh(v, f, seg_params=SegmentParams(max_rock_b=0.4), mesh_info=INFO)
    assert known.segmentation.scale.max_rock_b == 0.4
    assert len(known.rocks) == len(CENTRES)
    assert all(r.b == pytest.approx(0.4, rel=0.1) for r in known.rocks)
    assert not any('2.79 x 2.79 m' in w for w in known.report.warnings)


def test_a_rock_in_a_hollow_under_the_plane_is_measured_whole() -> None:
    # Ground 10 cm either side of z = 0: two boulders stand in hollows 5 cm under the plane,
    # which cuts off their lower half (a third of their volume is left without the largest rock).
    v, f = _boulders(0.1, 0.0)
    plane = analyse_mesh(v, f, mesh_info=INFO)
    assert min(r.volume for r in plane.rocks) < 0.5 * BOULDER_VOLUME
    known = analyse_mesh(v, f, seg_params=SegmentParams(max_rock_b=0.4), mesh_info=INFO)
    assert len(known.rocks) == len(CENTRES)
    assert all(r.volume == pytest.approx(BOULDER_VOLUME, rel=0.1) for r in known.rocks)
    assert all(r.b == pytest.approx(0.4, rel=0.1) for r in known.rocks)
