"""The rclpy node layer, run where ROS 2 Jazzy and the stockpile_msgs package are installed."""

from __future__ import annotations

import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

rclpy = pytest.importorskip(
    'rclpy',
    reason='rclpy (ROS 2 Jazzy) is not installed here: the node layer is exercised on the cart',
)
pytest.importorskip('stockpile_msgs', reason='the stockpile_msgs interface package is not built')

from rclpy.executors import MultiThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

from stockpile_ros.camera import CameraModel  # noqa: E402
from stockpile_ros.nodes.common import Inbox, RclpyFactory, qos_profile  # noqa: E402
from stockpile_ros.nodes.interfaces import get_message  # noqa: E402
from stockpile_ros.nodes.keyframe_node import KeyframeNode  # noqa: E402
from stockpile_ros.nodes.reconstruction_node import ReconstructionNode  # noqa: E402
from stockpile_ros.nodes.segmentation_node import SegmentationNode  # noqa: E402
from stockpile_ros.ros import messages as m  # noqa: E402
from stockpile_ros.ros import topics  # noqa: E402
from stockpile_ros.ros.outputs import diagnostic_array, pointcloud2  # noqa: E402
from stockpile_ros.settings import settings_for  # noqa: E402


def _call(client: Any, timeout: float = 5.0) -> Any:
    """Call a service and wait for the answer (the executor spins in another thread)."""
    future = client.call_async(Trigger.Request())
    deadline = time.monotonic() + timeout
    while not future.done() and time.monotonic() < deadline:
        time.sleep(0.02)
    assert future.done(), 'no answer from the service'
    return future.result()


def test_factory_builds_messages_rclpy_accepts() -> None:
    f = RclpyFactory()
    cloud = pointcloud2(f, [[0.0, 1.0, 2.0]], [[1, 2, 3]], [4], 5, 'stockpile')
    assert cloud.width == 1 and len(cloud.data) == cloud.point_step
    diag = diagnostic_array(f, 5, [{'name': 'a', 'level': 'WARN', 'message': 'm'}])
    assert diag.status[0].level == diag.status[0].WARN


class _Log:
    def __init__(self) -> None:
        self.errors: list[str] = []

    def error(self, text: str) -> None:
        self.errors.append(text)


def test_inbox_keeps_arrival_order_drops_oldest_frames_and_survives_errors() -> None:
    log = _Log()
    inbox = Inbox(max_droppable=2, logger=log)
    done: list[str] = []
    gate = threading.Event()
    inbox.put(lambda: gate.wait(5))  # holds the thread while the rest queues up
    for name in ['f1', 'odom1', 'f2', 'f3', 'odom2', 'f4']:
        inbox.put(lambda name=name: done.append(name), droppable=name.startswith('f'))

    def fail() -> None:
        raise ValueError('bad message')

    inbox.put(fail)
    inbox.put(lambda: done.append('after'))
    gate.set()
    assert inbox.drain(5)
    # Frames beyond two waiting went oldest first; the rest kept their order.
    assert done == ['odom1', 'f3', 'odom2', 'f4', 'after']
    assert inbox.dropped == 2
    assert len(log.errors) == 1 and 'bad message' in log.errors[0]
    inbox.close()


def test_parameters_declared_with_ranges(ros: None, tmp_path: Path) -> None:
    node = KeyframeNode(parameter_overrides=[Parameter('work_dir', value=str(tmp_path))])
    try:
        names = {s.name for s in settings_for('keyframes')}
        assert all(node.has_parameter(name) for name in names)
        descriptor = node.describe_parameter('selector.min_parallax')
        assert descriptor.floating_point_range[0].to_value == 1.0
        result = node.set_parameters([Parameter('selector.min_parallax', value=5.0)])[0]
        assert not result.successful
        assert not node.set_parameters([Parameter('work_dir', value='/x')])[0].successful
        # A value accepted at run time takes effect from the next frame on.
        assert node.set_parameters([Parameter('selector.min_parallax', value=0.5)])[0].successful
        assert node.inbox.drain(5)
        assert node.component.collector.selector.options.min_parallax == 0.5
    finally:
        node.destroy_node()


def test_second_trigger_while_busy_is_refused(ros: None, tmp_path: Path) -> None:
    node = ReconstructionNode(parameter_overrides=[Parameter('work_dir', value=str(tmp_path))])
    release = threading.Event()
    node.run = lambda stamp_ns: release.wait(5)  # type: ignore[method-assign]
    client_node = rclpy.create_node('stockpile_test_client')
    executor = MultiThreadedExecutor()
    executor.add_node(node)
    executor.add_node(client_node)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    try:
        client = client_node.create_client(Trigger, topics.RECONSTRUCT_SERVICE)
        assert client.wait_for_service(timeout_sec=5)
        first = _call(client)
        second = _call(client)
        assert first.success and not second.success
        assert 'already running' in second.message
        release.set()
        time.sleep(0.2)
        assert _call(client).success
    finally:
        release.set()
        executor.shutdown()
        node.destroy_node()
        client_node.destroy_node()


@pytest.mark.parametrize(
    ('name', 'value', 'why'),
    [
        ('segment.threshold', float('nan'), 'nan'),
        ('sfm.matcher', 'bogus', 'one of'),
        ('sfm.max_features', 10**9, ''),
        ('recon.target', 'charuco:1x1:0.08:0.06:DICT_4X4_50', 'charuco'),
        ('measure.specific_gravity', float('inf'), 'inf'),
    ],
)
def test_bad_parameter_values_are_refused_with_a_reason(
    ros: None, tmp_path: Path, name: str, value: object, why: str
) -> None:
    node = ReconstructionNode(parameter_overrides=[Parameter('work_dir', value=str(tmp_path))])
    if not node.has_parameter(name):
        node.destroy_node()
        node = SegmentationNode(parameter_overrides=[Parameter('work_dir', value=str(tmp_path))])
    try:
        before = node.get_parameter(name).value
        result = node.set_parameters([Parameter(name, value=value)])[0]
        assert not result.successful and result.reason
        assert why.lower() in result.reason.lower()
        assert node.get_parameter(name).value == before
        wrong_type = node.set_parameters([Parameter(name, value=[1, 2])])[0]
        assert not wrong_type.successful and wrong_type.reason
        assert node.get_parameter(name).value == before
    finally:
        node.destroy_node()


def test_bad_frames_give_diagnostics_and_the_node_keeps_running(ros: None, tmp_path: Path) -> None:
    params = [Parameter('work_dir', value=str(tmp_path)), Parameter('compressed', value=False)]
    node = KeyframeNode(parameter_overrides=params)
    probe = rclpy.create_node('stockpile_test_probe')
    got: dict[str, list[object]] = {'diag': [], 'status': []}
    entry = topics.topic(topics.DIAGNOSTICS)
    probe.create_subscription(get_message(entry.msgtype), entry.name,
                              got['diag'].append, qos_profile('reliable'))  # fmt: skip
    probe.create_subscription(get_message('stockpile_msgs/msg/PipelineStatus'),
                              topics.KEYFRAME_STATUS, got['status'].append,
                              qos_profile('latched'))  # fmt: skip
    camera = probe.create_publisher(get_message('sensor_msgs/msg/Image'), topics.IMAGE,
                                    qos_profile('sensor'))  # fmt: skip
    executor = MultiThreadedExecutor()
    executor.add_node(node)
    executor.add_node(probe)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    f = RclpyFactory()
    try:
        # The CameraInfo note waits for WAIT_NS of stream time: about 8 s of this loop on 2 cores.
        deadline = time.monotonic() + 30
        while camera.get_subscription_count() == 0 and time.monotonic() < deadline:
            time.sleep(0.05)
        bad = m.image(f, np.zeros((8, 8), np.uint8), 1, 'cam')
        bad.encoding = 'weird16'
        pixels = (np.arange(64 * 48 * 3) % 251).astype(np.uint8).reshape(48, 64, 3)
        texts: list[str] = []
        stamp = 0

        def heard() -> bool:
            # Both diagnostics by name: the CameraInfo one comes seconds after the first.
            return any('weird16' in t for t in texts) and any('no CameraInfo' in t for t in texts)

        while time.monotonic() < deadline and not (got['status'] and heard()):
            stamp += 100_000_000  # frames past the first keyframe's wait for a CameraInfo
            camera.publish(bad)
            camera.publish(m.image(f, pixels, stamp, 'cam'))
            time.sleep(0.1)
            texts = [st.message for d in list(got['diag']) for st in d.status]
        assert any('weird16' in t for t in texts), texts
        assert any('no CameraInfo' in t for t in texts), texts
        assert got['status'], 'the node stopped after a bad frame'
    finally:
        executor.shutdown()
        spinner.join(5)
        node.destroy_node()
        probe.destroy_node()


def test_a_quiet_check_while_the_first_frame_waits_in_the_inbox_keeps_its_camera(
    ros: None, tmp_path: Path
) -> None:
    """The camera's quiet time counts from a frame's arrival, not from when the inbox reads it."""
    params = [Parameter('work_dir', value=str(tmp_path)), Parameter('compressed', value=False),
              Parameter('recon.use_odometry', value=False)]  # fmt: skip
    node = KeyframeNode(parameter_overrides=params)
    callbacks = {topics.absolute(s.topic_name): s.callback for s in node.subscriptions}
    f = RclpyFactory()
    camera = CameraModel(64, 48, np.array([[60.0, 0, 32], [0, 60.0, 24], [0, 0, 1]]))
    pixels = (np.arange(64 * 48 * 3) % 251).astype(np.uint8).reshape(48, 64, 3)
    gate = threading.Event()
    try:
        node.last_image = time.monotonic() - 10  # the camera was quiet before the pass
        node.inbox.put(lambda: gate.wait(5))  # a busy inbox: what comes now waits in it
        callbacks[topics.absolute(topics.IMAGE)](m.image(f, pixels, 1, 'cam'))
        node.on_quiet()  # the timer, between the frame's arrival and its CameraInfo's
        callbacks[topics.absolute(topics.CAMERA_INFO)](m.camera_info(f, camera, 1))
        gate.set()
        assert node.inbox.drain(5)
        records = node.component.collector.store.records
        assert len(records) == 1 and records[0].camera is not None
    finally:
        gate.set()
        node.destroy_node()
