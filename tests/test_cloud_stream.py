"""PointCloud2 in: accumulated in the odometry frame through /tf, meshed by the replay's route."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from scipy.spatial.transform import Rotation

from stockpile_ros.artefacts import MeshInfo, load
from stockpile_ros.bagdrive import bag_inputs
from stockpile_ros.bagio.reader import BagReader
from stockpile_ros.bagio.writer import BagWriter
from stockpile_ros.cli import main
from stockpile_ros.cloud.accumulate import CloudAccumulator
from stockpile_ros.errors import StockpileError
from stockpile_ros.replay import replay
from stockpile_ros.ros import messages as m
from stockpile_ros.ros.messages import RosbagsFactory
from stockpile_ros.ros.outputs import pointcloud2
from stockpile_ros.ros.typestore import typestore
from stockpile_ros.settings import build_settings
from stockpile_ros.tools.sim.pile import PileConfig, parse_gradation
from stockpile_ros.tools.sim.survey import score_survey, simulate_survey, write_scan_bag

F = RosbagsFactory(typestore())
MOUNT = Rotation.from_euler('zy', [90.0, 25.0], degrees=True)
SECOND = 1_000_000_000


def _feed_cart(acc: CloudAccumulator, points: np.ndarray) -> None:
    """A cart driving along x at 1 m/s, its sensor up a 1.2 m mast, odometry at 10 Hz."""
    static = m.transform_stamped(F, 0, 'base_link', 'lidar', [0.0, 0.0, 1.2], MOUNT.as_quat())
    acc.on_tf(m.tf_message(F, [static]), True, 0)
    for k in range(31):
        t = k * SECOND // 10
        base = np.array([0.1 * k, -2.0, 0.0])
        acc.on_odometry(m.odometry(F, t, base, [0.0, 0.0, 0.0, 1.0]), t)
        if k % 10 == 5:
            # The cloud's stamp lies between two odometry samples: its pose is interpolated.
            stamp = t + SECOND // 20
            sensor = base + np.array([0.05, 0.0, 1.2])
            local = MOUNT.inv().apply(points - sensor)
            acc.on_cloud(pointcloud2(F, local, None, None, stamp, 'lidar'), stamp)


def test_clouds_are_placed_in_the_odometry_frame() -> None:
    rng = np.random.default_rng(0)
    points = rng.uniform([-1, -1, 0], [1, 1, 0.3], (500, 3))
    acc = CloudAccumulator(max_points=10_000)
    _feed_cart(acc, points)
    cloud, views = acc.cloud('points')
    assert acc.frame_id == 'odom' and acc.counts.placed == 3 and acc.counts.unplaced == 0
    np.testing.assert_allclose(cloud.points, np.vstack([points] * 3), atol=1e-5)
    # Each point keeps the way to its sensor: the first scan's sensor was at x = 0.55.
    towards = views[:500] - cloud.points[:500]
    expected = np.array([0.55, -2.0, 1.2]) - points
    expected /= np.linalg.norm(expected, axis=1, keepdims=True)
    np.testing.assert_allclose(towards, expected, atol=1e-5)


def test_clouds_without_a_pose_are_dropped_never_guessed() -> None:
    acc = CloudAccumulator(max_points=10_000)
    for k in range(11):
        t = k * SECOND // 10
        acc.on_odometry(m.odometry(F, t, [0.1 * k, 0.0, 0.0], [0, 0, 0, 1]), t)
    xyz = np.zeros((10, 3))
    # No transform links 'lidar' to base_link; and a stamp past the last odometry sample.
    acc.on_cloud(pointcloud2(F, xyz, None, None, SECOND // 2, 'lidar'), SECOND // 2)
    acc.on_cloud(pointcloud2(F, xyz, None, None, 5 * SECOND, 'base_link'), 5 * SECOND)
    # Points already in the odometry frame need no transform.
    acc.on_cloud(pointcloud2(F, xyz + 1, None, None, SECOND // 2, 'odom'), SECOND // 2)
    cloud, _ = acc.cloud('points')
    assert acc.counts.placed == 1 and acc.counts.unplaced == 2
    np.testing.assert_allclose(cloud.points, xyz + 1)


def test_a_fixed_sensor_without_odometry_and_thinning() -> None:
    acc = CloudAccumulator(max_points=3000)
    g = np.arange(0.0, 1.0, 0.02)
    x, y = np.meshgrid(g, g)
    grid = np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])
    for k in range(3):
        shifted = grid + np.array([0.01 * k / 3, 0.005 * k, 0.0])
        acc.on_cloud(pointcloud2(F, shifted, None, None, k * SECOND, 'scanner'), k * SECOND)
    acc.on_cloud(pointcloud2(F, grid, None, None, 4 * SECOND, 'other'), 4 * SECOND)
    cloud, _ = acc.cloud('points')
    assert acc.frame_id == 'scanner' and acc.counts.unplaced == 1
    assert acc.counts.thinned >= 1 and len(cloud.points) <= 3000
    # Thinned on a grid of the cloud's own spacing: the square is still covered.
    assert cloud.points[:, :2].min() < 0.03 and cloud.points[:, :2].max() > 0.95


def test_bag_inputs_find_the_cloud(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bag = tmp_path / 'bag'
    with BagWriter(bag) as writer:
        f = writer.factory
        xyz = np.zeros((3, 3))
        writer.write('/lidar/points', pointcloud2(f, xyz, None, None, SECOND, 'lidar'), SECOND)
        # The node set's own output, as in a replay.mcap: no sensor's.
        for k in range(3):
            msg = pointcloud2(f, xyz, None, None, SECOND, 'stockpile')
            writer.write('/stockpile/dense_cloud', msg, SECOND + k)
    with BagReader(bag) as reader:
        inputs = bag_inputs(reader)
        assert inputs.image is None and inputs.cloud == '/lidar/points'
        assert bag_inputs(reader, cloud_topic='lidar/points').cloud == '/lidar/points'
        with pytest.raises(StockpileError, match=r'cloud\.topic'):
            bag_inputs(reader, cloud_topic='points')
    # Structure-from-Motion needs a camera: the reason and the way out, not an empty run.
    assert main(['reconstruct', str(bag), '--work', str(tmp_path / 'work')]) == 2
    assert 'stockpile replay' in capsys.readouterr().err


def test_a_lidar_bag_replays_to_a_metric_result(tmp_path: Path) -> None:
    pile = PileConfig(rocks=16, gradation=parse_gradation('0.14:0.3'))
    survey = simulate_survey(tmp_path / 'truth', pile, seed=4, spacing=0.01, tilt_deg=0.0,
                             offset=(0.0, 0.0, 0.0))  # fmt: skip
    bag = write_scan_bag(tmp_path / 'bag', survey, scans=12)
    summary = replay(bag, tmp_path / 'out', build_settings({}))
    assert summary.ok and summary.cloud_topic == '/points' and summary.image_topic == ''
    info = load(MeshInfo, tmp_path / 'out' / 'work' / 'mesh' / 'mesh.json')
    assert info.scale.method == 'sensor' and info.units == 'm' and info.cloud is not None
    assert info.cloud['stream']['placed'] == 12 and info.cloud['stream']['frame_id'] == 'odom'
    assert 'towards its sensor' in info.cloud['normals']
    assert summary.report is not None and summary.report.units == 'm'
    scores = score_survey(tmp_path / 'out' / 'result', tmp_path / 'truth', survey, info)
    found = scores['detection']
    assert found['recall_visible'] >= 0.5 and found['precision_visible'] >= 0.7, found
    # The stockpile frame is placed in the odometry frame, as with keyframes.
    with AnyReader([tmp_path / 'out' / 'replay.mcap']) as reader:
        conns = [c for c in reader.connections if c.topic == '/tf_static']
        frames = [
            (tf.header.frame_id, tf.child_frame_id)
            for c, _, raw in reader.messages(connections=conns)
            for tf in reader.deserialize(raw, c.msgtype).transforms
        ]
    assert ('odom', 'stockpile') in frames
