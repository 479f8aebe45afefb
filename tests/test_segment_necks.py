from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pytest
from segment_fixtures import height_field

from stockpile_ros.segment.adjacency import FaceAdjacency, face_adjacency, face_geometry
from stockpile_ros.segment.cleanup import split_at_necks
from stockpile_ros.segment.params import SegmentParams
from stockpile_ros.segment.segmentation import segment_mesh

F64 = npt.NDArray[np.float64]


def _dumbbell(corridor: float) -> tuple[npt.NDArray[np.int32], FaceAdjacency, F64, F64]:
    """A flat grid (2 cm cells) labelled 1 on two discs of 0.3 m joined by a corridor, 2 beside."""
    v, f = height_field(lambda x, y: 0.0 * x, 1.0, 101)
    geom = face_geometry(v, f)
    x, y = geom.centroids[:, 0], geom.centroids[:, 1]
    discs = (np.hypot(x + 0.45, y) < 0.3) | (np.hypot(x - 0.45, y) < 0.3)
    labels = np.where(discs | ((np.abs(x) < 0.45) & (np.abs(y) < corridor)), 1, 0)
    labels[np.hypot(x, y - 0.75) < 0.2] = 2
    return labels.astype(np.int32), face_adjacency(f, len(v)), geom.areas, geom.centroids


def test_two_parts_joined_by_a_neck_are_split_there() -> None:
    labels, adj, areas, c = _dumbbell(corridor=0.05)
    out = split_at_necks(labels, adj, areas, rings=10, min_core=0.05)
    left, right = (out[np.argmin(np.hypot(c[:, 0] - x, c[:, 1]))] for x in (-0.45, 0.45))
    assert left != right and min(left, right) > 2
    # Every face of the region goes to a part, each disc to its own, the corridor cut mid-way.
    assert np.all((out > 0) == (labels > 0))
    assert np.all(out[(labels == 1) & (c[:, 0] < -0.05)] == left)
    assert np.all(out[(labels == 1) & (c[:, 0] > 0.05)] == right)
    # The other region is left as it was.
    assert np.array_equal(out == 2, labels == 2)


@pytest.mark.parametrize(
    ('corridor', 'min_core'),
    [
        (0.25, 0.05),  # a waist wider than the erosion is no neck
        (0.05, 0.2),  # cores under 0.1 m2 are too small to be parts
    ],
)
def test_a_region_without_a_neck_between_large_parts_stays_whole(
    corridor: float, min_core: float
) -> None:
    labels, adj, areas, _ = _dumbbell(corridor)
    assert np.array_equal(split_at_necks(labels, adj, areas, rings=10, min_core=min_core), labels)


def test_an_elongated_rock_has_no_neck() -> None:
    # A 3:1 dome, b 0.1 m at 2.5 mm edges: no waist, so the step leaves the regions it is given.
    def dome(x: F64, y: F64) -> F64:
        return 0.04 * np.sqrt(np.maximum(1.0 - (x / 0.15) ** 2 - (y / 0.05) ** 2, 0.0))

    v, f = height_field(dome, 0.2, 161)
    seen: dict[str, npt.NDArray[np.int32]] = {}
    seg = segment_mesh(
        v, f, SegmentParams(min_rock_b=0.05), on_step=lambda n, lab: seen.update({n: lab.copy()})
    )
    assert np.array_equal(seen['necks'], seen['fragments'])
    top = dome(seg.geometry.centroids[:, 0], seg.geometry.centroids[:, 1]) > 0.01
    assert np.bincount(seg.labels[top]).max() > 0.9 * top.sum()
