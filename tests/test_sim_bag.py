from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_typestore
from scipy.spatial.transform import Rotation

from stockpile_ros.cli import main
from stockpile_ros.errors import StockpileError
from stockpile_ros.meshio import read_labelled_mesh
from stockpile_ros.tools.sim.camera_path import PathConfig
from stockpile_ros.tools.sim.pile import PileConfig, parse_gradation
from stockpile_ros.tools.sim.record import SimulationConfig, simulate, truth_folder
from stockpile_ros.tools.sim.scene import SceneConfig

TINY = SimulationConfig(
    seed=4,
    scene=SceneConfig(
        pile=PileConfig(rocks=3, gradation=parse_gradation('0.12:0.18'), subdivisions=3),
        ground_px=256,
    ),
    path=PathConfig(kind='arc', heights=(1.0,)),
    width=96,
    height=72,
    fps=10.0,
    frames=4,
    odom_rate=20.0,
    threads=1,
)


def _read(bag: Path) -> dict[str, list[tuple[int, Any]]]:
    """Every message by topic, decoded with the plain Jazzy typestore of rosbags."""
    store = get_typestore(Stores.ROS2_JAZZY)
    out: dict[str, list[tuple[int, Any]]] = {}
    with Reader(bag) as reader:
        for conn, stamp, raw in reader.messages():
            out.setdefault(conn.topic, []).append((stamp, store.deserialize_cdr(raw, conn.msgtype)))
    return out


def _matrix(t: Any) -> np.ndarray:
    """4x4 of a geometry_msgs Pose or Transform."""
    pos = getattr(t, 'position', None) or t.translation
    q = getattr(t, 'orientation', None) or t.rotation
    m = np.eye(4)
    m[:3, :3] = Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix()
    m[:3, 3] = [pos.x, pos.y, pos.z]
    return m


def test_bag_decodes_and_odometry_and_tf_reproduce_the_true_cameras(tmp_path: Path) -> None:
    bag = tmp_path / 'pile'
    summary = simulate(TINY, bag)
    assert summary.truth == tmp_path / 'pile_truth'
    msgs = _read(bag)
    images = msgs['/camera/image_raw/compressed']
    infos = msgs['/camera/camera_info']
    assert len(images) == len(infos) == 4
    assert len(msgs['/odom']) == len(msgs['/tf']) == 7  # 0.3 s at 20 Hz
    truth = json.loads((summary.truth / 'truth.json').read_text())
    assert truth['schema'] == 'stockpile-truth/1' and truth['frame_id'] == 'odom'
    assert len(truth['cameras']) == 4
    for (stamp, img), (_, info), cam in zip(images, infos, truth['cameras'], strict=True):
        assert img.header.frame_id == 'camera_optical_frame' and img.format == 'jpeg'
        decoded = cv2.imdecode(img.data, cv2.IMREAD_COLOR)
        assert decoded.shape == (72, 96, 3)
        assert decoded.std() > 5  # textured, not blank
        assert stamp == cam['stamp_ns'] == img.header.stamp.sec * 10**9 + img.header.stamp.nanosec
        np.testing.assert_allclose(info.k, truth['camera']['k'])
        assert (info.width, info.height) == (96, 72)

    # odom -> base_link (from /odom) . base_link -> camera_link -> optical (from /tf_static)
    static = {t.child_frame_id: _matrix(t.transform) for t in msgs['/tf_static'][0][1].transforms}
    odom_at = {stamp: m for stamp, m in msgs['/odom']}
    tf_at = {stamp: m.transforms[0] for stamp, m in msgs['/tf']}
    for cam in truth['cameras']:
        odom = odom_at[cam['stamp_ns']]
        assert odom.header.frame_id == 'odom' and odom.child_frame_id == 'base_link'
        np.testing.assert_allclose(
            _matrix(tf_at[cam['stamp_ns']].transform), _matrix(odom.pose.pose)
        )
        pose = _matrix(odom.pose.pose) @ static['camera_link'] @ static['camera_optical_frame']
        np.testing.assert_allclose(pose[:3, 3], cam['position'], atol=1e-9)
        rot = Rotation.from_quat(cam['orientation_xyzw']).as_matrix()
        np.testing.assert_allclose(pose[:3, :3], rot, atol=1e-9)

    rocks = truth['rocks']
    assert [r['id'] for r in rocks] == [1, 2, 3]
    for r in rocks:
        assert r['a'] >= r['b'] >= r['c'] > 0
        assert r['mass'] == pytest.approx(r['volume'] * 2650)
        assert 0.0 < r['visible_fraction'] < 1.0
    grad = truth['gradation']
    assert grad['rock_count'] == 3 and grad['size_measure'] == 'b'
    assert grad['sizes'] == sorted(r['b'] for r in rocks)
    assert grad['total_mass'] == pytest.approx(sum(r['mass'] for r in rocks))
    assert grad['d100'] == pytest.approx(max(r['b'] for r in rocks))
    largest = max(rocks, key=lambda r: r['b'])
    assert grad['percent_passing_mass'][-2] == pytest.approx(
        100 * (1 - largest['mass'] / grad['total_mass'])
    )
    assert truth['target']['kind'] == 'charuco' and len(truth['target']['corners_world']) == 12
    mesh = read_labelled_mesh(summary.truth / 'scene.ply')
    assert set(np.unique(mesh.labels)) == {0, 1, 2, 3}
    # The centroid in the truth is the centroid of the labelled closed mesh.
    for r in rocks:
        faces = mesh.faces[mesh.labels == r['id']]
        p = mesh.vertices[faces]
        vol = np.einsum('ij,ij->i', p[:, 0], np.cross(p[:, 1], p[:, 2])) / 6
        assert vol.sum() == pytest.approx(r['volume'], rel=1e-5)
        centroid = (vol[:, None] * p.sum(axis=1)).sum(axis=0) / 4 / vol.sum()
        np.testing.assert_allclose(centroid, r['centroid'], atol=1e-5)


def test_same_seed_same_bag_other_seed_other_pile(tmp_path: Path) -> None:
    cfg = replace(TINY, frames=2, compressed=False, odom_noise=0.05, exposure=0.03)
    simulate(cfg, tmp_path / 'a')
    simulate(cfg, tmp_path / 'b')
    simulate(replace(cfg, seed=5), tmp_path / 'c')
    a, b, c = (_read(tmp_path / n) for n in 'abc')
    img_a = [m.data.tobytes() for _, m in a['/camera/image_raw']]
    assert img_a == [m.data.tobytes() for _, m in b['/camera/image_raw']]
    assert img_a != [m.data.tobytes() for _, m in c['/camera/image_raw']]
    assert a['/camera/image_raw'][0][1].encoding == 'rgb8'
    odom = [(m.pose.pose.position.x, m.pose.pose.position.y) for _, m in a['/odom']]
    assert odom == [(m.pose.pose.position.x, m.pose.pose.position.y) for _, m in b['/odom']]
    ta, tb, tc = ((tmp_path / f'{n}_truth' / 'truth.json').read_text() for n in 'abc')
    assert ta == tb and ta != tc


def test_two_heights_publish_the_mast_on_tf_and_noisy_odometry_drifts(tmp_path: Path) -> None:
    cfg = replace(
        TINY, path=PathConfig(heights=(0.8, 1.4), transition=0.2), frames=8, odom_noise=0.05
    )
    simulate(cfg, tmp_path / 'two')
    msgs = _read(tmp_path / 'two')
    assert {t.child_frame_id for t in msgs['/tf_static'][0][1].transforms} == {
        'camera_optical_frame'
    }
    mast = [m.transforms[1].transform.translation.z for _, m in msgs['/tf']]
    assert mast[0] == pytest.approx(0.8) and mast[-1] == pytest.approx(1.4)
    truth = json.loads((tmp_path / 'two_truth' / 'truth.json').read_text())
    heights = [c['position'][2] for c in truth['cameras']]
    assert heights[0] == pytest.approx(0.8) and heights[-1] == pytest.approx(1.4)
    # The first odometry pose is the true start; later ones drift, with a growing covariance.
    first, last = msgs['/odom'][0][1], msgs['/odom'][-1][1]
    assert first.pose.covariance[0] == 0 and last.pose.covariance[0] > 0


def test_cli_writes_bag_and_refuses_to_overwrite(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / 'cli'
    args = ['simulate', '--out', str(out), '--rocks', '2', '--frames', '2', '--width', '64',
            '--height', '48', '--raw', '--no-target', '--threads', '1',
            '--gradation', 'D15=0.1,D85=0.15']  # fmt: skip
    assert main(args) == 0
    assert 'true D50' in capsys.readouterr().out
    truth = json.loads((truth_folder(out) / 'truth.json').read_text())
    assert truth['target'] is None and len(truth['rocks']) == 2
    assert main(args) == 2
    assert 'exists already' in capsys.readouterr().err
    with pytest.raises(StockpileError):
        simulate(replace(TINY, frames=1), tmp_path / 'short')


def test_a_failed_run_leaves_no_half_written_bag(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from stockpile_ros.tools.sim import record

    def broken(*_: object) -> None:
        raise RuntimeError('renderer failed')

    monkeypatch.setattr(record.Renderer, 'render', broken)
    with pytest.raises(RuntimeError):
        simulate(TINY, tmp_path / 'broken')
    assert not (tmp_path / 'broken').exists()
