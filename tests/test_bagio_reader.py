from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer

from stockpile_ros.bagio.reader import (
    CAMERA_INFO_TOLERANCE_NS,
    BagReader,
    ReadStats,
    camera_info_topic_for,
    image_topics,
    read_frames,
    read_messages,
    read_odometry,
)
from stockpile_ros.bagio.writer import BagWriter
from stockpile_ros.camera import CameraModel
from stockpile_ros.errors import BagError
from stockpile_ros.ros import messages as m
from stockpile_ros.ros.typestore import typestore

FIXTURES = Path(__file__).resolve().parents[2] / 'shared' / 'fixtures'
RS_BAGS = FIXTURES / 'rosbags-rs'
OLD_BAG = FIXTURES / 'ros2bag_tools_images_bag' / 'images.bag'
needs_fixtures = pytest.mark.skipif(
    not RS_BAGS.is_dir() or not OLD_BAG.is_dir(),
    reason=f'fixture bags not found in {FIXTURES} (shared/ beside the repository)',
)

F = m.RosbagsFactory(typestore())
S = 1_000_000_000
CAM = CameraModel.from_fov(8, 6, 60.0, frame_id='cam_optical')
OTHER_CAM = CameraModel.from_fov(8, 6, 90.0, frame_id='cam_optical')


def rgb(seed: int) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 256, (6, 8, 3), dtype=np.uint8)


Item = tuple[str, Any, int]


def write_mcap(path: Path, items: list[Item]) -> Path:
    with BagWriter(path) as bag:
        for topic, msg, stamp in items:
            bag.write(topic, msg, stamp)
    return path


def write_sqlite(path: Path, items: list[Item]) -> Path:
    store = typestore()
    with Writer(path, version=9, storage_plugin=StoragePlugin.SQLITE3) as writer:
        conns: dict[str, Any] = {}
        for topic, msg, stamp in items:
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, msg.__msgtype__, typestore=store)
            writer.write(conns[topic], stamp, store.serialize_cdr(msg, msg.__msgtype__))
    return path


WRITERS = {'mcap': write_mcap, 'sqlite3': write_sqlite}


def camera_items(n: int = 3) -> list[Item]:
    items: list[Item] = []
    for i in range(n):
        t = (10 + i) * S
        items.append(('/cam/image_raw', m.image(F, rgb(i), t, 'cam_optical'), t))
        items.append(('/cam/camera_info', m.camera_info(F, CAM, t + 1000), t + 1000))
    return items


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_frames_with_camera_models(tmp_path: Path, storage: str) -> None:
    bag = WRITERS[storage](tmp_path / 'bag', camera_items())
    stats = ReadStats()
    frames = list(read_frames(bag, stats=stats))
    assert [f.stamp_ns for f in frames] == [10 * S, 11 * S, 12 * S]
    assert [f.index for f in frames] == [0, 1, 2]
    for i, frame in enumerate(frames):
        assert np.array_equal(frame.image, rgb(i))
        assert frame.frame_id == 'cam_optical' and frame.topic == '/cam/image_raw'
        assert frame.camera is not None and np.allclose(frame.camera.k, CAM.k)
        assert frame.camera.distortion_model == CAM.distortion_model
    assert stats.read['/cam/image_raw'] == 3 and stats.decoded['/cam/image_raw'] == 3
    assert stats.total_skipped == 0 and stats.problems == []


def test_compressed_topic_matches_camera_info_of_its_namespace(tmp_path: Path) -> None:
    items: list[Item] = []
    for i in range(2):
        t = (5 + i) * S
        img = m.compressed_image(F, rgb(i), t, 'left_optical', 'png')
        items.append(('/stereo/left/image_raw/compressed', img, t))
        info = m.camera_info(F, CAM if i == 0 else OTHER_CAM, t)
        items.append(('/stereo/left/camera_info', info, t))
        items.append(('/stereo/right/camera_info', m.camera_info(F, OTHER_CAM, t), t))
    bag = write_mcap(tmp_path / 'bag', items)
    frames = list(read_frames(bag))
    assert [np.array_equal(f.image, rgb(i)) for i, f in enumerate(frames)] == [True, True]
    # Nearest in time within the left namespace: CAM for the first frame, OTHER_CAM for the second.
    assert frames[0].camera is not None and np.allclose(frames[0].camera.k, CAM.k)
    assert frames[1].camera is not None and np.allclose(frames[1].camera.k, OTHER_CAM.k)


def test_camera_info_matched_by_frame_id_and_time(tmp_path: Path) -> None:
    late = 10 * S + CAMERA_INFO_TOLERANCE_NS + 1
    items: list[Item] = [
        ('/images', m.image(F, rgb(0), 10 * S, 'cam_optical'), 10 * S),
        ('/images', m.image(F, rgb(1), 20 * S, 'cam_optical'), 20 * S),
        ('/elsewhere/info', m.camera_info(F, CAM, 20 * S), 20 * S),
        ('/elsewhere/info', m.camera_info(F, OTHER_CAM, late + 30 * S), late + 30 * S),
    ]
    bag = write_mcap(tmp_path / 'bag', items)
    frames = list(read_frames(bag))
    # No CameraInfo in the namespace "/": matched by frame id; the first frame has none near it.
    assert frames[0].camera is None
    assert frames[1].camera is not None and np.allclose(frames[1].camera.k, CAM.k)


def test_static_camera_info_matches_any_time(tmp_path: Path) -> None:
    items: list[Item] = [
        ('/cam/camera_info', m.camera_info(F, CAM, 1 * S), 1 * S),
        ('/cam/camera_info', m.camera_info(F, CAM, 2 * S), 2 * S),
        ('/cam/image', m.image(F, rgb(0), 100 * S, 'other_frame'), 100 * S),
    ]
    frames = list(read_frames(write_mcap(tmp_path / 'bag', items)))
    assert frames[0].camera is not None


def test_camera_info_of_another_size_is_not_used(tmp_path: Path) -> None:
    big = CameraModel.from_fov(640, 480, 60.0, frame_id='cam_optical')
    items: list[Item] = [
        ('/cam/camera_info', m.camera_info(F, big, S), S),
        ('/cam/image_raw', m.image(F, rgb(0), S, 'cam_optical'), S),
    ]
    stats = ReadStats()
    frames = list(read_frames(write_mcap(tmp_path / 'bag', items), stats=stats))
    assert frames[0].camera is None
    assert any('CameraInfo is 640x480 but images are 8x6' in p for p in stats.problems)


def test_uncalibrated_camera_info_is_a_counted_problem(tmp_path: Path) -> None:
    zero = CameraModel(8, 6, np.zeros((3, 3)), frame_id='cam_optical')
    items: list[Item] = [
        ('/cam/camera_info', m.camera_info(F, zero, S), S),
        ('/cam/image_raw', m.image(F, rgb(0), S, 'cam_optical'), S),
    ]
    stats = ReadStats()
    frames = list(read_frames(write_mcap(tmp_path / 'bag', items), stats=stats))
    assert len(frames) == 1 and frames[0].camera is None
    assert stats.skipped == {'/cam/camera_info': 1}
    assert 'topic /cam/camera_info, message 0: CameraInfo is uncalibrated' in stats.problems[0]


def short_image(t: int) -> Any:
    msg = m.image(F, rgb(0), t, 'cam_optical')
    msg.data = msg.data[:30]
    return msg


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_short_image_is_skipped_and_counted(tmp_path: Path, storage: str) -> None:
    items = camera_items()
    items.insert(2, ('/cam/image_raw', short_image(int(10.5 * S)), int(10.5 * S)))
    bag = WRITERS[storage](tmp_path / 'bag', items)
    stats = ReadStats()
    frames = list(read_frames(bag, '/cam/image_raw', stats=stats))
    assert [f.index for f in frames] == [0, 2, 3]
    assert stats.read['/cam/image_raw'] == 4 and stats.decoded['/cam/image_raw'] == 3
    assert stats.skipped == {'/cam/image_raw': 1}
    assert stats.problems == [
        f'{bag}, topic /cam/image_raw, message 1: data holds 30 bytes but 8x6 rgb8 with step 24 '
        'needs 144'
    ]
    with pytest.raises(BagError) as err:
        list(read_frames(bag, skip_bad=False))
    assert (err.value.topic, err.value.index) == ('/cam/image_raw', 1)
    assert str(err.value).startswith(f'{bag}, topic /cam/image_raw, message 1: data holds 30')


def test_undecodable_cdr_is_a_counted_problem(tmp_path: Path) -> None:
    store = typestore()
    path = tmp_path / 'bag'
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection('/cam/image_raw', 'sensor_msgs/msg/Image', typestore=store)
        good = store.serialize_cdr(m.image(F, rgb(0), S, 'c'), 'sensor_msgs/msg/Image')
        writer.write(conn, S, good)
        writer.write(conn, 2 * S, bytes(good[:40]))
    stats = ReadStats()
    got = list(read_messages(path, ['/cam/image_raw'], stats=stats))
    assert [(topic, index) for topic, index, _, _ in got] == [('/cam/image_raw', 0)]
    assert stats.skipped == {'/cam/image_raw': 1}
    assert 'message 1: cannot decode sensor_msgs/msg/Image' in stats.problems[0]
    with pytest.raises(BagError, match='message 1: cannot decode'):
        list(read_messages(path, ['/cam/image_raw'], skip_bad=False))


def test_image_topics_most_messages_first(tmp_path: Path) -> None:
    items = camera_items(3)
    items.append(('/b/image/compressed', m.compressed_image(F, rgb(0), S, 'b'), S))
    bag = write_mcap(tmp_path / 'bag', items)
    assert image_topics(bag) == ['/cam/image_raw', '/b/image/compressed']
    assert [f.topic for f in read_frames(bag, '/b/image/compressed')] == ['/b/image/compressed']


def test_topic_errors(tmp_path: Path) -> None:
    bag = write_mcap(tmp_path / 'bag', camera_items(1))
    with pytest.raises(BagError, match=r'/cam/camera_info is not an image topic'):
        list(read_frames(bag, '/cam/camera_info'))
    with pytest.raises(
        BagError, match=r'no topic /nope \(topics: /cam/camera_info, /cam/image_raw\)'
    ):
        list(read_messages(bag, ['/nope']))
    empty = write_mcap(
        tmp_path / 'odom_only', [('/odom', m.odometry(F, S, [0, 0, 0], [0, 0, 0, 1]), S)]
    )
    with pytest.raises(BagError, match='no Image or CompressedImage topic'):
        list(read_frames(empty))


def test_odometry_from_odometry_topic(tmp_path: Path) -> None:
    items: list[Item] = [
        ('/odom', m.odometry(F, 2 * S, [2, 0, 0], [0, 0, 0, 1]), 2 * S),
        ('/odom', m.odometry(F, 1 * S, [1, 0, 0], [0, 0, 0, 1]), 3 * S),
        (
            '/tf',
            m.tf_message(
                F, [m.transform_stamped(F, S, 'odom', 'base_link', [9, 9, 9], [0, 0, 0, 1])]
            ),
            S,
        ),
    ]
    poses = read_odometry(write_sqlite(tmp_path / 'bag', items))
    assert [p.stamp_ns for p in poses] == [S, 2 * S]
    assert poses[0].position.tolist() == [1.0, 0.0, 0.0]
    assert (poses[0].frame_id, poses[0].child_frame_id) == ('odom', 'base_link')


def test_odometry_from_tf(tmp_path: Path) -> None:
    def tf(t: int, parent: str, child: str, x: float) -> Any:
        return m.transform_stamped(F, t, parent, child, [x, 0, 0], [0, 0, 0.6, 0.8])

    items: list[Item] = [
        (
            '/tf',
            m.tf_message(F, [tf(S, 'odom', 'base_link', 1.0), tf(S, 'base_link', 'cam', 5.0)]),
            S,
        ),
        ('/tf', m.tf_message(F, [tf(2 * S, '/odom', 'base_link', 2.0)]), 2 * S),
        ('/tf_static', m.tf_message(F, [tf(0, 'odom', 'base_link', 7.0)]), S),
    ]
    poses = read_odometry(write_mcap(tmp_path / 'bag', items))
    assert [p.position[0] for p in poses] == [1.0, 2.0]
    assert np.allclose(poses[1].orientation_xyzw, [0, 0, 0.6, 0.8])
    assert read_odometry(write_mcap(tmp_path / 'none', camera_items(1))) == []


def test_camera_info_topic_for() -> None:
    infos = ['/cam/camera_info', '/other/camera_info', '/camera_info']
    assert camera_info_topic_for('/cam/image_raw', infos) == '/cam/camera_info'
    assert camera_info_topic_for('/cam/image_raw/compressed', infos) == '/cam/camera_info'
    assert camera_info_topic_for('/cam/image_rect/compressedDepth', infos) == '/cam/camera_info'
    assert camera_info_topic_for('/image', infos) == '/camera_info'
    assert camera_info_topic_for('/x/image', infos) is None


def test_bad_paths(tmp_path: Path) -> None:
    with pytest.raises(BagError, match='no such file or folder'):
        image_topics(tmp_path / 'missing')
    (tmp_path / 'notes.txt').write_text('hello')
    with pytest.raises(BagError, match='not a ROS 2 bag'):
        image_topics(tmp_path / 'notes.txt')
    (tmp_path / 'old.bag').write_bytes(b'#ROSBAG V2.0\n')
    with pytest.raises(BagError, match='ROS 1 bags are not supported'):
        image_topics(tmp_path / 'old.bag')
    (tmp_path / 'empty').mkdir()
    with pytest.raises(BagError, match=r'not a rosbag2 folder: no metadata\.yaml'):
        image_topics(tmp_path / 'empty')
    (tmp_path / 'junk.mcap').write_bytes(b'\x89MCAP0\r\n' + b'\x00' * 20)
    with pytest.raises(BagError, match=r'junk\.mcap: cannot open the bag'):
        image_topics(tmp_path / 'junk.mcap')
    broken = tmp_path / 'broken'
    broken.mkdir()
    (broken / 'metadata.yaml').write_text('rosbag2_bagfile_information: {version: 5}\n')
    with pytest.raises(BagError, match='broken: cannot open the bag'):
        list(read_frames(broken))


def test_truncated_mcap_says_so(tmp_path: Path) -> None:
    bag = write_mcap(tmp_path / 'bag', camera_items(3))
    mcap = next(bag.glob('*.mcap'))
    data = mcap.read_bytes()
    mcap.write_bytes(data[: len(data) // 2])
    with pytest.raises(BagError, match=r'cannot open the bag: .*MCAP file is truncated'):
        list(read_frames(bag))


def test_storage_file_and_bag_named_folder(tmp_path: Path) -> None:
    bag = write_sqlite(tmp_path / 'cam.bag', camera_items(2))
    assert len(list(read_frames(bag))) == 2
    db3 = next(bag.glob('*.db3'))
    assert len(list(read_frames(db3))) == 2
    (bag / 'metadata.yaml').unlink()
    assert len(list(read_frames(bag))) == 2  # the single .db3 inside still reads


@needs_fixtures
@pytest.mark.parametrize('name', ['test_bag_mcap', 'test_bag_sqlite3'])
def test_fixture_bags_with_bad_images(name: str) -> None:
    bag = RS_BAGS / name
    with BagReader(bag) as reader:
        topics = reader.image_topics()
        assert topics == ['/test/sensor_msgs/compressed_image', '/test/sensor_msgs/image']
        stats = ReadStats()
        for topic in topics:
            assert list(reader.frames(topic, stats=stats)) == []
        assert stats.skipped == {
            '/test/sensor_msgs/compressed_image': 2,
            '/test/sensor_msgs/image': 2,
        }
        problems = '\n'.join(stats.problems)
        assert 'topic /test/sensor_msgs/image, message 1: data holds 30 bytes' in problems
        assert 'topic /test/sensor_msgs/compressed_image, message 0: truncated JPEG: 10' in problems
        with pytest.raises(BagError) as err:
            list(reader.frames('/test/sensor_msgs/image', skip_bad=False))
        assert (err.value.bag, err.value.topic, err.value.index) == (
            str(bag),
            '/test/sensor_msgs/image',
            0,
        )
        poses = reader.odometry()
        assert len(poses) == 2 and poses[0].position.tolist() == [1.0, 2.0, 0.0]
        # Every other message of the ~94 types deserialises.
        counts = ReadStats()
        every = sorted({c.topic for c in reader.reader.connections})
        assert len(list(reader.messages(every, stats=counts))) == 188
        assert counts.total_skipped == 0


@needs_fixtures
def test_fixture_older_sqlite3_layout() -> None:
    # No message definitions in this bag: types come from the Jazzy typestore.
    frames = list(read_frames(OLD_BAG))
    assert [f.stamp_ns for f in frames] == [0, S, 2 * S]
    assert all(f.image.shape == (2, 2) and f.image.dtype == np.uint8 for f in frames)
    assert all(f.frame_id == 'camera_optical_frame' and f.camera is None for f in frames)
