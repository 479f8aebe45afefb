from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from stockpile_ros.bagio.summary import format_summary, summarize
from stockpile_ros.bagio.writer import BagWriter
from stockpile_ros.camera import CameraModel
from stockpile_ros.cli import main
from stockpile_ros.ros import messages as m

FIXTURES = Path(__file__).resolve().parents[2] / 'shared' / 'fixtures'
FIXTURE_BAGS = {
    'mcap': FIXTURES / 'rosbags-rs' / 'test_bag_mcap',
    'sqlite3': FIXTURES / 'rosbags-rs' / 'test_bag_sqlite3',
    'old_sqlite3': FIXTURES / 'ros2bag_tools_images_bag' / 'images.bag',
}
needs_fixtures = pytest.mark.skipif(
    not all(p.is_dir() for p in FIXTURE_BAGS.values()),
    reason=f'fixture bags not found in {FIXTURES} (shared/ beside the repository)',
)
S = 1_000_000_000


def write_capture(path: Path) -> Path:
    cam = CameraModel.from_fov(8, 6, 60.0, frame_id='cam_optical')
    img = np.zeros((6, 8, 3), np.uint8)
    with BagWriter(path) as bag:
        f = bag.factory
        for i in range(5):
            t = 100 * S + i * S // 4  # 4 Hz
            bag.write('/cam/image_raw', m.image(f, img, t, 'cam_optical'), t)
            bag.write('/cam/camera_info', m.camera_info(f, cam, t), t)
            bag.write('/cam/image_raw/compressed', m.compressed_image(f, img, t, 'cam_optical'), t)
            bag.write('/odom', m.odometry(f, t, [i, 0, 0], [0, 0, 0, 1]), t)
        short = m.image(f, img, 102 * S, 'cam_optical')
        short.data = short.data[:10]
        bag.write('/cam/image_raw', short, 102 * S)
    return path


def test_summary_of_a_capture(tmp_path: Path) -> None:
    bag = write_capture(tmp_path / 'capture')
    s = summarize(bag)
    assert s.storage == 'mcap' and s.layout is None and s.message_count == 21
    assert (s.start_ns, s.end_ns, s.duration_s) == (100 * S, 102 * S, 2.0)
    topics = {t.name: t for t in s.topics}
    assert sorted(topics) == [
        '/cam/camera_info',
        '/cam/image_raw',
        '/cam/image_raw/compressed',
        '/odom',
    ]
    raw = topics['/cam/image_raw']
    assert raw.msgtype == 'sensor_msgs/msg/Image' and raw.count == 6 and raw.image is not None
    assert (raw.image.decoded, raw.image.bad) == (5, 1)
    assert raw.image.sizes == ['8x6'] and raw.image.encodings == ['rgb8']
    assert raw.image.camera_info == '/cam/camera_info' and raw.image.with_camera == 5
    assert raw.image.frame_rate_hz == pytest.approx(4.0)
    jpeg = topics['/cam/image_raw/compressed'].image
    assert jpeg is not None and jpeg.encodings == ['jpeg'] and jpeg.with_camera == 5
    assert topics['/odom'].image is None
    assert s.odometry == '/odom (nav_msgs/Odometry)' and s.odometry_poses == 5
    assert s.problems == [
        f'{bag}, topic /cam/image_raw, message 5: data holds 10 bytes but 8x6 rgb8 with step 24 '
        'needs 144'
    ]
    text = format_summary(s)
    assert 'storage:   mcap' in text and 'duration:  2.000 s' in text
    assert '5/6 decoded; size 8x6; encoding rgb8; 4.00 Hz; camera_info /cam/camera_info' in text
    assert 'problems:  1' in text and 'message 5: data holds 10 bytes' in text


def test_summary_without_decoding(tmp_path: Path) -> None:
    s = summarize(write_capture(tmp_path / 'capture'), decode=False)
    raw = next(t for t in s.topics if t.name == '/cam/image_raw')
    assert raw.image is not None and raw.image.decoded == 0 and raw.image.sizes == []
    assert s.problems == [] and 'problems:  not checked' in format_summary(s)


def test_empty_bag(tmp_path: Path) -> None:
    with BagWriter(tmp_path / 'empty'):
        pass
    s = summarize(tmp_path / 'empty')
    assert s.message_count == 0 and s.start_ns is None and s.topics == []
    assert 'odometry:  none' in format_summary(s)


def test_cli_json_and_errors(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bag = write_capture(tmp_path / 'capture')
    assert main(['info', '--json', str(bag)]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data['message_count'] == 21 and len(data['problems']) == 1
    assert main(['info', str(tmp_path / 'missing')]) == 2
    err = capsys.readouterr().err
    assert err.strip() == f'stockpile info: error: {tmp_path / "missing"}: no such file or folder'


@needs_fixtures
@pytest.mark.parametrize('name', sorted(FIXTURE_BAGS))
def test_info_on_fixture_bags(name: str, capsys: pytest.CaptureFixture[str]) -> None:
    bag = FIXTURE_BAGS[name]
    assert main(['info', '--json', str(bag)]) == 0
    captured = capsys.readouterr()
    assert 'Traceback' not in captured.err
    data = json.loads(captured.out)
    images = {t['name']: t['image'] for t in data['topics'] if t['image'] is not None}
    if name == 'old_sqlite3':
        assert data['storage'] == 'sqlite3' and data['layout'].startswith('older rosbag2 layout')
        assert data['message_count'] == 3 and data['duration_s'] == pytest.approx(2.0)
        assert images['/image']['decoded'] == 3 and images['/image']['sizes'] == ['2x2']
        assert images['/image']['encodings'] == ['mono8'] and data['problems'] == []
        assert images['/image']['frame_rate_hz'] == pytest.approx(1.0)
    else:
        assert data['storage'] == name and len(data['topics']) == 94
        assert data['message_count'] == 188 and data['duration_s'] == pytest.approx(18.7)
        assert {k: (v['decoded'], v['bad']) for k, v in images.items()} == {
            '/test/sensor_msgs/compressed_image': (0, 2),
            '/test/sensor_msgs/image': (0, 2),
        }
        assert images['/test/sensor_msgs/image']['camera_info'] == '/test/sensor_msgs/camera_info'
        assert len(data['problems']) == 4
        assert data['odometry'] == '/test/nav_msgs/odometry (nav_msgs/Odometry)'
    assert main(['info', str(bag)]) == 0
    text = capsys.readouterr().out
    assert text.startswith(f'bag:       {bag}') and 'problems:' in text
