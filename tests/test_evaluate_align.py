from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from stockpile_ros.tools.evaluation.align import (
    align_trajectories,
    match_stamps,
    nearest_rotation,
    rotation_angle,
)
from stockpile_ros.tools.evaluation.inputs import EvaluationError, Poses


def _random_similarity(seed: int) -> tuple[float, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    return (
        float(rng.uniform(0.2, 5.0)),
        Rotation.random(random_state=seed).as_matrix(),
        rng.normal(size=3) * 10,
    )


def test_rotation_helpers() -> None:
    rot = Rotation.from_rotvec([0.0, 0.0, 0.3]).as_matrix()
    assert rotation_angle(rot) == pytest.approx(0.3, abs=1e-15)
    assert rotation_angle(np.eye(3)) == 0.0
    assert rotation_angle(Rotation.from_rotvec([np.pi, 0, 0]).as_matrix()) == pytest.approx(np.pi)
    np.testing.assert_allclose(nearest_rotation(2.0 * rot), rot, atol=1e-12)


def test_match_stamps_nearest_within_tolerance() -> None:
    truth = np.array([300, 100, 200, 400], dtype=np.int64)
    result = np.array([99, 205, 251, 1000, 400], dtype=np.int64)
    ri, ti = match_stamps(result, truth, tolerance_ns=10)
    assert ri.tolist() == [0, 1, 4]
    assert truth[ti].tolist() == [100, 200, 400]
    ri, ti = match_stamps(result, truth, tolerance_ns=0)
    assert ri.tolist() == [4]
    assert ti.tolist() == [3]
    ri, _ = match_stamps(result, np.zeros(0, dtype=np.int64), tolerance_ns=10)
    assert len(ri) == 0


def _poses(centres: np.ndarray, rots: np.ndarray, stamps: np.ndarray) -> Poses:
    return Poses(stamps.astype(np.int64), centres.astype(float), rots.astype(float))


def _moved(p: Poses, s: float, rot: np.ndarray, t: np.ndarray) -> Poses:
    """The same trajectory expressed in a frame where truth x maps to s R x + t."""
    return _poses(s * p.centres @ rot.T + t, rot @ p.rotations, p.stamps_ns)


def test_align_general_trajectory_exactly() -> None:
    n = 12
    ang = np.linspace(0, 2, n)
    centres = np.stack([2 * np.cos(ang), 2 * np.sin(ang), 1 + 0.1 * ang], axis=1)
    rots = Rotation.random(n, random_state=5).as_matrix()
    truth = _poses(centres, rots, np.arange(n) * 33_000_000)
    s, rot, t = _random_similarity(6)
    result = _moved(truth, s, rot, t)
    al = align_trajectories(result, truth, 'stockpile', 'odom')
    assert al.method == 'umeyama'
    assert al.matched == n
    assert al.scale == pytest.approx(1 / s, rel=1e-12)
    np.testing.assert_allclose(al.apply(result.centres), centres, atol=1e-10)
    assert al.centre_errors.max() < 1e-10
    assert al.orientation_errors.max() < 1e-7


def test_align_collinear_trajectory_uses_orientations() -> None:
    n = 10
    centres = np.stack([np.linspace(0, 3, n), np.full(n, -1.5), np.full(n, 1.0)], axis=1)
    rots = Rotation.from_euler('x', np.linspace(-2.0, -2.2, n)[:, None]).as_matrix()
    truth = _poses(centres, rots, np.arange(n) * 50_000_000)
    s, rot, t = _random_similarity(7)
    result = _moved(truth, s, rot, t)
    al = align_trajectories(result, truth, 'stockpile', 'odom')
    assert al.method == 'centres+orientations'
    assert 'collinear' in al.note
    assert al.scale == pytest.approx(1 / s, rel=1e-12)
    np.testing.assert_allclose(al.rotation, rot.T, atol=1e-12)
    # Points off the line land right too, which centres alone could not ensure.
    off_line = np.array([[0.3, 2.0, -0.4]])
    np.testing.assert_allclose(al.apply(s * off_line @ rot.T + t), off_line, atol=1e-10)


def test_align_with_too_few_keyframes() -> None:
    centres = np.array([[0.0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1.5]])
    rots = np.repeat(np.eye(3)[None], 4, axis=0)
    stamps = np.arange(4) * 100_000_000
    truth = _poses(centres, rots, stamps)
    result = _poses(centres[:2], rots[:2], stamps[:2])
    with pytest.raises(EvaluationError, match=r'2 of 2 keyframes.*differs from the truth frame'):
        align_trajectories(result, truth, 'stockpile', 'odom')
    al = align_trajectories(result, truth, 'odom', 'odom')
    assert al.method == 'identity'
    assert al.scale == 1.0
    assert 'without alignment' in al.note
    # Stamps further apart than the tolerance do not pair up.
    late = _poses(centres, rots, stamps + 6_000_000)
    with pytest.raises(EvaluationError, match=r'0 of 4 keyframes match .* within 5 ms'):
        align_trajectories(late, truth, 'stockpile', 'odom')
    al = align_trajectories(late, truth, 'stockpile', 'odom', 7_000_000)
    assert (al.method, al.matched) == ('umeyama', 4)
    assert al.centre_errors.max() < 1e-12
