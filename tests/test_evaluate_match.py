from __future__ import annotations

import numpy as np
import pytest

from stockpile_ros.tools.evaluation.match import (
    OFF_SURFACE,
    LabelTransfer,
    MatchOptions,
    match_rocks,
    split_faces,
)


def _areas(tri: np.ndarray) -> np.ndarray:
    return 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)


def test_split_faces_keeps_area_and_parents() -> None:
    vertices = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0.05, 0, 0], [0, 0.05, 0]])
    faces = np.array([[0, 1, 2], [0, 3, 4]])
    pieces, parent = split_faces(vertices, faces, max_edge=0.3)
    # The big face needs 3 rounds (hypotenuse 1.41 -> 0.18), the small one none.
    assert np.bincount(parent).tolist() == [64, 1]
    np.testing.assert_allclose(np.bincount(parent, weights=_areas(pieces)), [0.5, 0.00125])
    edges = np.linalg.norm(pieces - np.roll(pieces, -1, axis=1), axis=2)
    assert edges.max() <= 0.3
    unsplit, same = split_faces(vertices, faces, max_edge=0.0)
    assert same.tolist() == [0, 1]
    np.testing.assert_array_equal(unsplit, vertices[faces])


def test_match_rocks_overlap_iou_and_assignment() -> None:
    # Pieces: result labels, true labels, areas.
    result = np.array([1, 1, 1, 2, 2, 0, 3])
    true = np.array([10, 10, 20, 20, 20, 20, OFF_SURFACE])
    areas = np.array([3.0, 1.0, 1.0, 2.0, 1.0, 1.0, 2.0])
    transfer = LabelTransfer(np.arange(7), true, np.zeros(7), areas)
    m = match_rocks(result, transfer, [1, 2, 3], [10, 20, 30], MatchOptions())
    np.testing.assert_allclose(m.result_area, [5.0, 3.0, 2.0])
    np.testing.assert_allclose(m.true_area, [4.0, 5.0, 0.0])
    # IoU(1, 10) = 4 / (5 + 4 - 4); IoU(2, 20) = 3 / (3 + 5 - 3).
    np.testing.assert_allclose(m.iou[:, :2], [[0.8, 1 / 9], [0.0, 0.6], [0.0, 0.0]])
    assert m.pairs == [(1, 10, pytest.approx(0.8)), (2, 20, pytest.approx(0.6))]
    assert m.false_reasons == {3: 'off-surface'}
    assert m.merges == {} and m.splits == {}
