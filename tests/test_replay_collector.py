"""The keyframe collector shared by the keyframe node and the replay."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from stockpile_ros.artefacts import OdometryEntry
from stockpile_ros.camera import Frame
from stockpile_ros.recon.collector import KeyframeCollector, OdometryBuffer, heading_coverage
from stockpile_ros.recon.keyframes import SelectorOptions
from stockpile_ros.ros import messages as m
from stockpile_ros.ros.typestore import typestore


def test_heading_coverage() -> None:
    assert heading_coverage([]) == 0.0
    assert heading_coverage([0.3]) == 0.0
    full = list(np.linspace(0, 2 * math.pi, 40))
    assert heading_coverage(full) == pytest.approx(1.0)
    quarter = heading_coverage(list(np.linspace(0.05, 0.05 + math.pi / 2, 10)))
    assert 0.22 < quarter < 0.3
    # Back and forth over the same arc counts once; the short way across +-pi is taken.
    assert heading_coverage([0.05, 1.0, 0.05, 1.0]) == heading_coverage([0.05, 1.0])
    assert heading_coverage([math.pi - 0.1, -math.pi + 0.1]) < 0.1


def _texture(shift: int) -> np.ndarray:
    rng = np.random.default_rng(0)
    big = (rng.random((120, 400)) * 255).astype(np.uint8)
    big = np.kron(big, np.ones((2, 2), dtype=np.uint8))
    grey = big[:160, shift : shift + 200]
    return np.repeat(grey[:, :, None], 3, axis=2).copy()


def _quat(yaw: float) -> list[float]:
    return [0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)]


def test_collects_stores_and_resumes(tmp_path: Path) -> None:
    options = SelectorOptions(min_spacing=1, min_parallax=0.05, reference_frames=3)
    folder = tmp_path / 'keyframes'
    collector = KeyframeCollector(folder, options, full_parallax=1.0)
    for i in range(12):
        frame = Frame(1000 * i, _texture(8 * i), 'cam', None, 'cam/image', i)
        collector.push(frame, None)
    state = collector.state
    assert state.frames == 12
    assert state.decisions.get('first') == 1
    assert 2 <= state.keyframes < 12
    assert state.coverage_source == 'parallax' and 0 < state.coverage <= 1
    assert len(list(folder.glob('kf_*.png'))) == state.keyframes
    again = KeyframeCollector(folder, options)
    assert again.state.keyframes == state.keyframes
    # With odometry the coverage is the heading sweep.
    odo = KeyframeCollector(tmp_path / 'odo', options)
    for i in range(12):
        frame = Frame(1000 * i, _texture(8 * i), 'cam', None, 'cam/image', i)
        odo.push(frame, OdometryEntry([0.0, 0.0, 0.0], _quat(0.2 * i)))
    assert odo.state.coverage_source == 'odometry'
    assert 0.2 < odo.state.coverage < 0.7


def test_odometry_buffer_interpolates_between_the_samples_on_both_sides() -> None:
    buf = OdometryBuffer(max_gap_ns=2000)
    assert buf.at(0) is None and not buf.covers(0)
    buf.push(1000, (1.0, 2.0, 3.0), (0.0, 0.0, 0.0, 1.0), 'odom', 'base_link')
    assert buf.at(1500) is None and not buf.covers(1500)  # nothing after the stamp yet
    buf.push(2000, (5.0, 2.0, 3.0), (0.0, 0.0, 0.0, 1.0), 'odom', 'base_link')
    assert buf.covers(1500) and buf.latest_ns == 2000
    entry = buf.at(1750)
    assert entry is not None and entry.position == pytest.approx([4.0, 2.0, 3.0])
    assert (entry.frame_id, entry.child_frame_id) == ('odom', 'base_link')
    assert buf.at(2500) is None  # after the last sample
    buf.push(5000, (9.0, 2.0, 3.0), (0.0, 0.0, 0.0, 1.0), 'odom', 'base_link')
    assert buf.at(3000) is None  # across a gap longer than max_gap_ns


def test_odometry_buffer_places_the_camera_with_the_live_transforms() -> None:
    # base_link at x = 1 facing +y (90 deg about z); the camera 0.5 m ahead of the base on a mast
    # that rises from 0.2 to 0.4 m between two /tf samples, then a fixed optical frame.
    f = m.RosbagsFactory(typestore())
    yaw = (0.0, 0.0, math.sin(math.pi / 4), math.cos(math.pi / 4))
    buf = OdometryBuffer()
    buf.push(1000, (1.0, 0.0, 0.0), yaw, 'odom', 'base_link')
    unlinked = buf.at(1000, 'camera_optical_frame')
    assert unlinked is not None and unlinked.camera_position is None
    level = (0.0, 0.0, 0.0, 1.0)
    mount = m.transform_stamped(f, 0, 'camera_link', 'camera_optical_frame', (0, 0, 0), level)
    buf.tree.add(m.tf_message(f, [mount]), static=True, log_ns=0)
    for stamp, z in ((900, 0.2), (1100, 0.4)):
        mast = m.transform_stamped(f, stamp, 'base_link', 'camera_link', (0.5, 0.0, z), level)
        buf.tree.add(m.tf_message(f, [mast]), static=False, log_ns=stamp)
    entry = buf.at(1000, 'camera_optical_frame')
    assert entry is not None
    assert entry.camera_position == pytest.approx([1.0, 0.5, 0.3])
    assert entry.position == [1.0, 0.0, 0.0]
