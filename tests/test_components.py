"""The ROS-free components on hand-made message streams: order, waiting, bad samples, hand-off."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from stockpile_ros.camera import CameraModel
from stockpile_ros.components import KeyframeComponent, ReconstructionComponent
from stockpile_ros.ros import messages as m
from stockpile_ros.ros import topics
from stockpile_ros.ros.typestore import typestore
from stockpile_ros.settings import build_settings

F = m.RosbagsFactory(typestore())
MS = 1_000_000
CAMERA = CameraModel(64, 48, np.array([[60.0, 0, 32], [0, 60.0, 24], [0, 0, 1]]), np.zeros(5),
                     'plumb_bob', 'camera_optical')  # fmt: skip
# Every sharp frame is a keyframe: the tests are about what each keyframe carries.
EVERY = {'selector.min_parallax': 0.0, 'selector.min_spacing': 1, 'selector.blur_ratio': 0.0}


def _component(tmp_path: Path, **values: Any) -> KeyframeComponent:
    return KeyframeComponent(build_settings({**EVERY, 'work_dir': str(tmp_path), **values}), F)


def _image(i: int, shape: tuple[int, int] = (48, 64)) -> Any:
    pixels = (np.random.default_rng(i).random((*shape, 3)) * 255).astype(np.uint8)
    return m.image(F, pixels, 1000 * MS + i * 100 * MS, 'camera_optical')


def _odom(stamp_ns: int, x: float, quat: tuple[float, ...] = (0.0, 0.0, 0.0, 1.0)) -> Any:
    return m.odometry(F, stamp_ns, (x, 0.0, 0.0), quat)


def _mount() -> Any:
    level = (0.0, 0.0, 0.0, 1.0)
    mount = m.transform_stamped(F, 0, 'base_link', 'camera_optical', (0.0, 0.0, 1.5), level)
    return m.tf_message(F, [mount])


def _kept(publications: list[tuple[str, Any]]) -> list[Any]:
    return [msg for name, msg in publications if name == topics.KEYFRAMES]


def _diagnostics(publications: list[tuple[str, Any]]) -> list[tuple[str, str]]:
    return [(s.name, s.message) for name, msg in publications if name == topics.DIAGNOSTICS
            for s in msg.status]  # fmt: skip


def test_a_keyframe_waits_for_the_odometry_after_its_stamp_and_is_interpolated(
    tmp_path: Path,
) -> None:
    kf = _component(tmp_path)
    out = kf.on_tf(_mount(), True, 0)
    out += kf.on_camera_info(m.camera_info(F, CAMERA, 1000 * MS), 1000 * MS)
    out += kf.on_odometry(_odom(950 * MS, 1.0), 0)
    image = _image(0)
    out += kf.on_image(image, 0)
    assert not _kept(out) and kf.pending == 1  # odometry has not passed the stamp yet
    # Announced all the same: a reconstruction triggered now waits for it.
    assert [msg for name, msg in out if name == topics.KEYFRAME_STATUS][-1].keyframes == 1
    sent = _kept(kf.on_odometry(_odom(1050 * MS, 2.0), 0))
    assert len(sent) == 1 and kf.pending == 0
    key = sent[0]
    assert key.has_odometry and key.base_pose.position.x == pytest.approx(1.5)
    assert key.has_camera_pose and key.camera_pose.position.z == pytest.approx(1.5)
    assert key.has_camera_info and key.camera_info.width == 64


def test_topic_order_does_not_change_the_keyframe(tmp_path: Path) -> None:
    """Live, the image overtakes its CameraInfo and odometry; the keyframe must not change."""

    def feed(order: str, folder: Path) -> Any:
        kf = _component(folder)
        kf.on_tf(_mount(), True, 0)
        image, info = _image(0), m.camera_info(F, CAMERA, 1000 * MS)
        steps = {'i': lambda: kf.on_image(image, 0), 'c': lambda: kf.on_camera_info(info, 0),
                 'a': lambda: kf.on_odometry(_odom(950 * MS, 1.0), 0),
                 'b': lambda: kf.on_odometry(_odom(1050 * MS, 2.0), 0)}  # fmt: skip
        sent = [msg for step in order for msg in _kept(steps[step]())]
        assert len(sent) == 1, order
        return sent[0]

    reference = feed('cabi', tmp_path / 'ref')
    for order in ('icab', 'iabc', 'aibc', 'bica'):
        key = feed(order, tmp_path / order)
        assert key.base_pose == reference.base_pose and key.camera_pose == reference.camera_pose
        assert key.has_camera_info and key.camera_info.k.tolist() == CAMERA.k.ravel().tolist()


def test_without_odometry_or_camera_info_a_keyframe_goes_after_the_wait(tmp_path: Path) -> None:
    kf = _component(tmp_path)
    waited = [p for i in range(21) for p in kf.on_image(_image(i), 0)]  # 2 s of frames
    assert not _kept(waited)
    out = kf.on_image(_image(21), 0)
    sent = _kept(out)
    assert sent and not sent[0].has_odometry and not sent[0].has_camera_info
    assert any('no CameraInfo' in text for _, text in _diagnostics(out))
    assert kf.counts.without_odometry >= 1


def test_bad_poses_are_left_out_with_one_warning(tmp_path: Path) -> None:
    kf = _component(tmp_path)
    out = kf.on_odometry(_odom(900 * MS, 1.0, (0.0, 0.0, 0.0, 0.0)), 0)
    out += kf.on_odometry(_odom(950 * MS, math.nan), 0)
    zero = m.transform_stamped(F, 0, 'base_link', 'camera_optical', (0, 0, 1), (0, 0, 0, 0))
    out += kf.on_tf(m.tf_message(F, [zero]), True, 0)
    assert kf.counts.bad_poses == 3 and kf.odometry.latest_ns is None
    assert 'camera_optical' not in kf.odometry.tree.static
    texts = [text for name, text in _diagnostics(out) if name == 'stockpile/odometry']
    assert len(texts) == 2 and all('zero quaternion' in t for t in texts)  # odometry, tf
    kf.on_odometry(_odom(1000 * MS, 1.0, (0.0, 0.0, 0.0, 2.0)), 0)  # normalised, kept
    assert kf.odometry.latest_ns == 1000 * MS


def test_frames_of_another_size_are_skipped(tmp_path: Path) -> None:
    kf = _component(tmp_path)
    kf.on_image(_image(0), 0)
    out = kf.on_image(_image(1, (96, 128)), 0)
    assert any('image size changed from 64x48 to 128x96' in t for _, t in _diagnostics(out))
    assert sum(kf.counts.skipped.values()) == 1 and kf.collector.state.frames == 1


def test_the_reconstruction_stores_each_keyframe_once_and_counts_the_missing(
    tmp_path: Path,
) -> None:
    kf = _component(tmp_path / 'cart')
    kf.on_camera_info(m.camera_info(F, CAMERA, 0), 0)
    out = [p for i in range(4) for p in kf.on_image(_image(i), 0)] + kf.flush(0)
    sent = _kept(out)
    rc = ReconstructionComponent(build_settings({'work_dir': str(tmp_path / 'base')}), F)
    status = [msg for name, msg in out if name == topics.KEYFRAME_STATUS][-1]
    rc.on_keyframe_status(status)
    assert rc.wait_for_keyframes(0.05) == len(sent)  # none has arrived yet
    for key in [*sent, sent[0]]:  # a repeat is ignored
        rc.on_keyframe(key, 0)
    assert rc.wait_for_keyframes(0.05) == 0 and rc.held.keyframes == len(sent) == 4
    records = rc.store.records
    assert [r.index for r in records] == [k.frame_index for k in sent]
    assert all(r.camera is not None and r.camera.width == 64 for r in records)
