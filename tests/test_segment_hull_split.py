from __future__ import annotations

from collections.abc import Callable

import numpy as np
import numpy.typing as npt
import pytest
from segment_fixtures import height_field

from stockpile_ros.segment.adjacency import FaceGeometry, face_adjacency, face_geometry
from stockpile_ros.segment.cleanup import split_under_hulls
from stockpile_ros.segment.params import SegmentParams
from stockpile_ros.segment.segmentation import segment_mesh

F64 = npt.NDArray[np.float64]


def _cap(x: F64, y: F64, at: float, r: float = 0.1, h: float = 0.05) -> F64:
    return h * np.sqrt(np.maximum(1.0 - ((x - at) / r) ** 2 - (y / r) ** 2, 0.0))


def _split(
    z: Callable[[F64, F64], F64],
    depth: float,
    min_part: float,
    outside: Callable[[F64], npt.NDArray[np.bool_]] | None = None,
) -> tuple[npt.NDArray[np.int32], npt.NDArray[np.int32], FaceGeometry]:
    """One region on the faces of ``z`` above 5 mm (2 mm cells), split under its hull.

    The region is 12 cm wide but narrows to 6 cm at x = 0, as two touching rocks do in plan.
    """
    v, f = height_field(z, 0.3, 301)
    geom = face_geometry(v, f)
    x, y, h = geom.centroids.T
    inside = (h > 0.005) & (np.abs(y) < 0.06 - 0.03 * np.exp(-((x / 0.03) ** 2)))
    labels = inside.astype(np.int32)
    skip = np.zeros(len(f), dtype=bool) if outside is None else outside(geom.centroids)
    adj = face_adjacency(f, len(v))
    return split_under_hulls(v, geom, labels, adj, f, depth, min_part, skip), labels, geom


def _two_caps(x: F64, y: F64) -> F64:
    # Two rocks 0.2 m wide touching 0.18 m apart: the crease between them lies 28 mm under the
    # plane across their tops.
    return np.maximum(_cap(x, y, -0.09), _cap(x, y, 0.09))


def test_two_touching_rocks_in_one_region_are_split_at_the_crease() -> None:
    out, labels, geom = _split(_two_caps, depth=0.001, min_part=0.005)
    x = geom.centroids[:, 0]
    left, right = (
        out[np.argmin(np.hypot(x + 0.09, geom.centroids[:, 1]))],
        out[np.argmin(np.hypot(x - 0.09, geom.centroids[:, 1]))],
    )
    assert left != right and min(left, right) > 1
    # Every face of the region goes to a part, each rock to its own.
    assert np.all((out > 0) == (labels > 0))
    assert np.all(out[(labels > 0) & (x < -0.01)] == left)
    assert np.all(out[(labels > 0) & (x > 0.01)] == right)


@pytest.mark.parametrize(
    ('depth', 'min_part'),
    [
        (0.04, 0.005),  # the crease (28 mm under the tops) is shallower than that
        (0.001, 0.05),  # the region (0.047 m2) is smaller than a part must be
    ],
)
def test_a_crease_too_shallow_or_a_region_too_small_leave_the_region_whole(
    depth: float, min_part: float
) -> None:
    out, labels, _ = _split(_two_caps, depth, min_part)
    assert np.array_equal(out, labels)


def test_rocks_each_smaller_than_a_part_taken_for_one_are_no_rock() -> None:
    # Each rock shows under 0.04 m2, the region over it: fines under the smallest rock of
    # interest, taken for one rock of its size.
    out, labels, _ = _split(_two_caps, depth=0.001, min_part=0.04)
    assert labels.any() and not out.any()


@pytest.mark.parametrize(('min_part', 'kept'), [(0.018, True), (0.022, False)])
def test_a_region_stays_whole_where_one_of_its_parts_is_a_rock_of_interest(
    min_part: float, kept: bool
) -> None:
    # A rock with a pebble beside it, 0.027 m2 together: the rock's part reaches 0.018 m2, not
    # 0.022 m2, and the pebble's neither.
    def rock_and_pebble(x: F64, y: F64) -> F64:
        return np.maximum(_cap(x, y, -0.03), _cap(x, y, 0.1, r=0.03, h=0.02))

    out, labels, _ = _split(rock_and_pebble, depth=0.001, min_part=min_part)
    assert labels.any()
    assert np.array_equal(out, labels) if kept else not out.any()


def test_one_convex_rock_lies_on_its_hull_and_stays_whole() -> None:
    # A 3:1 rock, 0.3 x 0.1 m: no face of it is under its hull by more than the mesh's chords.
    def long_cap(x: F64, y: F64) -> F64:
        return 0.05 * np.sqrt(np.maximum(1.0 - (x / 0.15) ** 2 - (y / 0.05) ** 2, 0.0))

    out, labels, _ = _split(long_cap, depth=0.001, min_part=0.001)
    assert np.array_equal(out, labels)


def test_faces_left_out_of_every_rock_neither_shape_the_hull_nor_hold_a_part() -> None:
    # The right rock's faces are valley faces: the left rock alone shapes the hull, lies on it,
    # and nothing is split.
    out, labels, _ = _split(_two_caps, depth=0.001, min_part=0.005, outside=lambda c: c[:, 0] > 0.0)
    assert np.array_equal(out, labels)


def test_the_default_mode_splits_two_rocks_the_search_ran_across() -> None:
    # A test that passes every edge makes the search run across the crease; the convex join
    # after the split leaves the two apart.
    seen: dict[str, npt.NDArray[np.int32]] = {}
    v, f = height_field(_two_caps, 0.3, 301)
    params = SegmentParams(min_rock_b=0.1, threshold=-1.0, valley_depth_ratio=0.0)
    seg = segment_mesh(v, f, params, on_step=lambda n, lab: seen.update({n: lab.copy()}))
    c = seg.geometry.centroids
    left, right = (seg.labels[np.argmin(np.hypot(c[:, 0] - x, c[:, 1]))] for x in (-0.09, 0.09))
    assert 'hull split' in seen and left != right and min(left, right) > 0
    assert np.unique(seen['undersides'][c[:, 2] > 0.02]).size == 1
