"""The valley test (a crease at the scale of a centimetre) and the hand-back of valley faces."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import numpy.typing as npt
import pytest
from segment_fixtures import height_field

from stockpile_ros.segment.adjacency import FaceAdjacency, face_geometry
from stockpile_ros.segment.segmentation import SegmentParams, hand_back, segment_mesh, valley_faces

F64 = npt.NDArray[np.float64]


def _domes(x: F64, y: F64) -> F64:
    """Two 5 cm domes 9 cm apart, their crease rounded over about a centimetre (a soft max)."""
    radius, rounding = 0.05, 0.01
    d = [np.sqrt(np.maximum(radius**2 - (x - cx) ** 2 - y**2, 0.0)) for cx in (-0.045, 0.045)]
    return np.asarray(rounding * np.logaddexp(d[0] / rounding, d[1] / rounding))


def _valley_area_near(v: F64, f: npt.NDArray[np.int64], x0: float) -> tuple[float, float]:
    geom = face_geometry(v, f)
    valley = valley_faces(v, f, geom, radius=0.0075, depth=0.0005)
    near = np.abs(geom.centroids[:, 0] - x0) < 0.01
    return float(geom.areas[valley & near].sum()), float(geom.areas[valley & ~near].sum())


@pytest.mark.parametrize('kind', ['valley', 'roof'])
def test_a_valley_is_found_along_the_crease_and_a_roof_is_not(kind: str) -> None:
    slope = 0.3 if kind == 'valley' else -0.3
    v, f = height_field(lambda x, y: slope * np.abs(x), 0.1, 81)
    near, far = _valley_area_near(v, f, 0.0)
    assert far == 0.0
    assert (near > 0.0) == (kind == 'valley')


def test_the_valley_scale_is_metric_not_a_count_of_faces() -> None:
    coarse = _valley_area_near(*height_field(lambda x, y: 0.3 * np.abs(x), 0.1, 81), 0.0)[0]
    fine = _valley_area_near(*height_field(lambda x, y: 0.3 * np.abs(x), 0.1, 241), 0.0)[0]
    assert fine == pytest.approx(coarse, rel=0.25)


def test_hand_back_splits_a_band_where_the_fronts_meet() -> None:
    # A strip of 10 faces in a row: 1 | free x 8 | 2.
    adj = FaceAdjacency(10, np.arange(9), np.arange(1, 10))
    labels = np.array([1] + [0] * 8 + [2], dtype=np.int32)
    free = np.array([False] + [True] * 8 + [False])
    assert hand_back(labels, adj, free).tolist() == [1] * 5 + [2] * 5


def test_the_search_stops_at_a_rounded_crease() -> None:
    v, f = height_field(_domes, 0.1, 161)
    seg = segment_mesh(v, f)
    assert seg.raw_regions == 2
    xy = seg.geometry.centroids[:, :2]
    tops = [np.argmin(np.linalg.norm(xy - [x, 0.0], axis=1)) for x in (-0.045, 0.045)]
    assert seg.labels[tops[0]] != seg.labels[tops[1]]
    assert min(seg.labels[tops]) > 0
    # Valley faces went back to the domes: all that is left unlabelled is ground.
    assert np.all(seg.geometry.centroids[seg.labels == 0, 2] < SegmentParams().ground_tolerance)
    # Without the valley test the face-to-face criterion alone breaks the same mesh into pieces.
    assert segment_mesh(v, f, replace(SegmentParams(), valley_depth=0.0)).raw_regions > 2
