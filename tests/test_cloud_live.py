"""The live reconstruction node meshes a PointCloud2 stream (where ROS 2 Jazzy is installed)."""

from __future__ import annotations

import json
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

from stockpile_ros.nodes.common import RclpyFactory, qos_profile  # noqa: E402
from stockpile_ros.nodes.interfaces import get_message  # noqa: E402
from stockpile_ros.nodes.reconstruction_node import ReconstructionNode  # noqa: E402
from stockpile_ros.ros import topics  # noqa: E402
from stockpile_ros.ros.outputs import pointcloud2  # noqa: E402


def _bumps() -> np.ndarray:
    """A fixed scanner's view of a few boulders on the ground, in its own frame (z up)."""
    g = np.arange(-0.6, 0.6, 0.01)
    x, y = np.meshgrid(g, g, indexing='ij')
    z = np.zeros_like(x)
    for cx, cy, r in ((-0.25, -0.2, 0.18), (0.2, 0.1, 0.22), (-0.1, 0.3, 0.15)):
        z = np.maximum(z, np.sqrt(np.clip(r**2 - (x - cx) ** 2 - (y - cy) ** 2, 0, None)))
    return np.column_stack([x.ravel(), y.ravel(), z.ravel()])


def test_the_node_meshes_a_point_cloud_stream(ros: None, tmp_path: Path) -> None:
    node = ReconstructionNode(parameter_overrides=[Parameter('work_dir', value=str(tmp_path))])
    probe = rclpy.create_node('stockpile_test_cloud_probe')
    got: list[Any] = []
    entry = topics.topic(topics.SURFACE)
    probe.create_subscription(get_message(entry.msgtype), entry.name, got.append,
                              qos_profile(entry.qos))  # fmt: skip
    cloud_entry = topics.topic(topics.CLOUD)
    sensor = probe.create_publisher(get_message(cloud_entry.msgtype), cloud_entry.name,
                                    qos_profile(cloud_entry.qos))  # fmt: skip
    client = probe.create_client(Trigger, topics.RECONSTRUCT_SERVICE)
    executor = MultiThreadedExecutor()
    executor.add_node(node)
    executor.add_node(probe)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    try:
        deadline = time.monotonic() + 20
        while sensor.get_subscription_count() == 0 and time.monotonic() < deadline:
            time.sleep(0.05)
        points = _bumps()
        f = RclpyFactory()
        # Two sweeps of a scanner on a tripod (no odometry: its own frame is the model frame).
        for k, half in enumerate((points[::2], points[1::2])):
            sensor.publish(pointcloud2(f, half, None, None, (k + 1) * 10**9, 'scanner'))
        while node.component.clouds.counts.placed < 2 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert node.component.clouds.counts.placed == 2
        assert client.wait_for_service(timeout_sec=5)
        future = client.call_async(Trigger.Request())
        while not got and time.monotonic() < deadline + 40:
            time.sleep(0.1)
        assert future.done() and future.result().success
        assert got, 'no surface published'
        info = json.loads(got[0].info)
        assert info['scale']['method'] == 'sensor'
        assert info['cloud']['stream'] == {'frame_id': 'scanner', 'messages': 2, 'placed': 2,
                                           'unplaced': 0, 'bad': 0, 'thinned': 0}  # fmt: skip
        assert len(got[0].faces) > 1000
    finally:
        executor.shutdown()
        spinner.join(5)
        node.destroy_node()
        probe.destroy_node()
