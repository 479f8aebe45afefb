"""Every message type we publish, written to MCAP and read back by a plain rosbags reader.

The reader is not handed our .msg files: stockpile_msgs types must decode from the definitions the
MCAP file embeds.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from rosbags.interfaces import MessageDefinitionFormat
from rosbags.typesys import Stores, get_typestore

from stockpile_ros.artefacts import ScaleRecord
from stockpile_ros.bagio.writer import BagWriter
from stockpile_ros.camera import CameraModel
from stockpile_ros.result import ClassDecision, GradationRecord, Intervals, RockRecord
from stockpile_ros.ros import messages as m
from stockpile_ros.ros import outputs as o
from stockpile_ros.ros.images import decode_image

STAMP = 1_700_000_000_123_456_789

ROCKS = [
    RockRecord(
        id=1,
        centroid=[0.1, 0.2, 0.15],
        orientation_xyzw=[0.0, 0.0, math.sin(0.25), math.cos(0.25)],
        a=0.4,
        b=0.3,
        c=0.2,
        esd=0.31,
        volume=0.0156,
        mass=41.3,
        visible_area=0.21,
        visible_fraction=0.55,
        fer=2.0,
        sphericity=0.81,
        confidence=0.9,
    ),
    RockRecord(
        id=7,
        centroid=[1.0, -0.5, 0.1],
        orientation_xyzw=[0.0, 0.0, 0.0, 1.0],
        a=0.25,
        b=0.2,
        c=0.12,
        esd=0.19,
        volume=0.0036,
        mass=9.5,
        visible_area=0.08,
        visible_fraction=math.nan,
        fer=2.08,
        sphericity=math.nan,
        confidence=0.4,
    ),
]
SCALE = ScaleRecord('target+odometry', 0.98, None)
GRADATION = GradationRecord(
    size_measure='b',
    sizes=[0.2, 0.3],
    percent_passing_count=[50.0, 100.0],
    percent_passing_mass=[18.7, 100.0],
    d10=None,
    d15=None,
    d30=0.22,
    d50=0.26,
    d60=0.27,
    d85=0.29,
    d100=0.3,
    cu=None,
    cc=None,
    rock_count=2,
    total_mass=50.8,
    spec=ClassDecision('FHWA Class III', 'mass', True, False, 'FAIL', ['too few']),
    intervals=Intervals('none', 0.9, 0, 0, 0.0, {}, {}, [None, None], [None, None]),
    rosin_rammler=None,
    sieves=[],
)


def _scene() -> dict[str, Any]:
    rng = np.random.default_rng(5)
    yy, xx = np.mgrid[0:24, 0:32]
    # Smooth, so that JPEG keeps it close.
    rgb = np.stack([xx * 8, yy * 10, 255 - xx * 4], axis=2).astype(np.uint8)
    points = rng.normal(size=(50, 3))
    colors = rng.integers(0, 256, (50, 3), dtype=np.uint8)
    labels = rng.integers(0, 9, 50)
    vertices = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.5]], dtype=float)
    faces = np.array([[0, 1, 2], [1, 3, 2]])
    return {
        'rgb': rgb,
        'points': points,
        'colors': colors,
        'labels': labels,
        'vertices': vertices,
        'faces': faces,
        'face_labels': np.array([1, 0]),
        'camera': CameraModel.from_fov(32, 24, 60.0),
    }


def _write(path: Path, s: dict[str, Any]) -> None:
    with BagWriter(path) as bag:
        f = bag.factory
        bag.write('/cam/image_raw', m.image(f, s['rgb'], STAMP, 'cam'), STAMP)
        bag.write(
            '/cam/image_raw/compressed', m.compressed_image(f, s['rgb'], STAMP, 'cam', 'png'), STAMP
        )
        bag.write('/cam/jpeg', m.compressed_image(f, s['rgb'], STAMP, 'cam', 'jpeg'), STAMP)
        bag.write('/cam/camera_info', m.camera_info(f, s['camera'], STAMP), STAMP)
        bag.write('/odom', m.odometry(f, STAMP, [1, 2, 3], [0, 0, 0, 1], position_sigma=0.1), STAMP)
        tf = m.transform_stamped(f, STAMP, 'odom', 'base_link', [4, 5, 6], [0, 0, 1, 0])
        bag.write('/tf', m.tf_message(f, [tf]), STAMP)
        cloud = o.pointcloud2(f, s['points'], s['colors'], s['labels'], STAMP, 'stockpile')
        bag.write('/cloud', cloud, STAMP)
        bag.write('/markers', o.marker_array(f, ROCKS, STAMP, 'stockpile'), STAMP)
        mesh_markers = o.marker_array(
            f, ROCKS, STAMP, 'stockpile', s['vertices'], s['faces'], s['face_labels']
        )
        bag.write('/mesh_markers', mesh_markers, STAMP)
        entries = [
            {'name': 'sfm', 'level': 'WARN', 'message': 'few', 'values': {'registered': 12}},
            {'name': 'camera', 'level': 0, 'message': 'ok', 'hardware_id': 'cam0'},
        ]
        bag.write('/diagnostics', o.diagnostic_array(f, STAMP, entries), STAMP)
        bag.write('/rock', o.rock_msg(f, ROCKS[0], STAMP, 'stockpile'), STAMP)
        bag.write('/rocks', o.rock_array(f, ROCKS, SCALE, STAMP, 'stockpile'), STAMP)
        bag.write('/gradation', o.gradation_msg(f, GRADATION, STAMP, 'stockpile'), STAMP)
        status = o.pipeline_status(f, STAMP, 'segmenting', 'segment', 0.5, 30, 0.8, 'busy', 'wait')
        bag.write('/status', status, STAMP)


def _read(path: Path, default: Any) -> dict[str, Any]:
    out = {}
    with AnyReader([path], default_typestore=default) as reader:
        for conn in reader.connections:
            assert conn.msgdef.format != MessageDefinitionFormat.NONE, conn.topic
        for conn, _, raw in reader.messages():
            out[conn.topic] = reader.deserialize(raw, conn.msgtype)
    return out


def _same(value: float, expected: float | None) -> bool:
    return math.isnan(value) if expected is None else value == pytest.approx(expected)


@pytest.mark.parametrize('default', ['none', 'jazzy'])
def test_every_published_type_round_trips(tmp_path: Path, default: str) -> None:
    s = _scene()
    path = tmp_path / 'out'
    _write(path, s)
    store = get_typestore(Stores.ROS2_JAZZY) if default == 'jazzy' else None
    got = _read(path, store)

    assert np.array_equal(decode_image(got['/cam/image_raw']), s['rgb'])
    assert np.array_equal(decode_image(got['/cam/image_raw/compressed']), s['rgb'])
    jpeg = decode_image(got['/cam/jpeg']).astype(int)
    assert jpeg.shape == s['rgb'].shape and np.abs(jpeg - s['rgb']).mean() < 6
    assert got['/cam/image_raw'].header.stamp.sec == STAMP // 10**9
    assert got['/cam/image_raw'].header.stamp.nanosec == STAMP % 10**9

    info = got['/cam/camera_info']
    assert np.allclose(info.k, s['camera'].k.reshape(-1)) and info.width == 32

    odom = got['/odom']
    assert [odom.pose.pose.position.x, odom.pose.pose.position.z] == [1.0, 3.0]
    assert odom.pose.covariance[0] == pytest.approx(0.01) and odom.child_frame_id == 'base_link'
    tf = got['/tf'].transforms[0]
    assert tf.child_frame_id == 'base_link' and tf.transform.rotation.z == 1.0

    cloud = got['/cloud']
    assert [fld.name for fld in cloud.fields] == ['x', 'y', 'z', 'rgb', 'label']
    xyz, colors, labels = o.pointcloud2_arrays(cloud)
    assert np.allclose(xyz, s['points'].astype(np.float32))
    assert np.array_equal(colors, s['colors']) and np.array_equal(labels, s['labels'])

    markers = got['/markers'].markers
    assert markers[0].action == 3  # DELETEALL
    cubes = [mk for mk in markers if mk.ns == 'rocks']
    texts = [mk for mk in markers if mk.ns == 'rock_labels']
    assert [mk.id for mk in cubes] == [1, 7] and all(mk.type == 1 for mk in cubes)
    assert cubes[0].scale.x == pytest.approx(0.4) and cubes[0].pose.orientation.w == pytest.approx(
        math.cos(0.25)
    )
    assert cubes[1].pose.orientation.w == 1.0
    assert texts[0].type == 9 and texts[0].text == '1: b 30.0 cm'
    assert (cubes[0].color.r, cubes[0].color.g) != (cubes[1].color.r, cubes[1].color.g)
    mesh = got['/mesh_markers'].markers
    tri = next(mk for mk in mesh if mk.ns == 'rocks' and mk.id == 1)
    assert tri.type == 11 and len(tri.points) == 3
    # Rock 7 has no face in the mesh: it falls back to its oriented box.
    assert next(mk for mk in mesh if mk.ns == 'rocks' and mk.id == 7).type == 1

    diag = got['/diagnostics'].status
    assert [d.name for d in diag] == ['sfm', 'camera'] and [d.level for d in diag] == [1, 0]
    assert (diag[0].values[0].key, diag[0].values[0].value) == ('registered', '12')
    assert diag[1].hardware_id == 'cam0'

    rock = got['/rock']
    assert rock.id == 1 and rock.centroid.z == pytest.approx(0.15)
    assert rock.flat_elongated_ratio == 2.0 and rock.orientation.z == pytest.approx(math.sin(0.25))
    array = got['/rocks']
    assert array.metric is True and array.scale_method == 'target+odometry'
    assert math.isnan(array.scale_rel_uncertainty)
    second = array.rocks[1]
    assert second.id == 7 and math.isnan(second.visible_fraction) and math.isnan(second.sphericity)
    assert second.mass == pytest.approx(9.5) and second.orientation.w == 1.0

    grad = got['/gradation']
    for key in ('d10', 'd15', 'd30', 'd50', 'd60', 'd85', 'd100', 'cu', 'cc', 'total_mass'):
        assert _same(getattr(grad, key), getattr(GRADATION, key)), key
    assert list(grad.sizes) == [0.2, 0.3] and list(grad.percent_passing_mass) == [18.7, 100.0]
    assert grad.rock_count == 2 and grad.spec_class == 'FHWA Class III'
    assert grad.checked is True and grad.passed is False and list(grad.reasons) == ['too few']
    assert grad.verdict == 'FAIL' and grad.units == 'm'

    status = got['/status']
    assert status.state == 3 and status.stage == 'segment' and status.keyframes == 30
    assert status.progress == pytest.approx(0.5) and status.advice == 'wait'


def test_builders_reject_bad_input() -> None:
    from stockpile_ros.ros.typestore import typestore

    f = m.RosbagsFactory(typestore())
    with pytest.raises(ValueError, match='Nx3'):
        o.pointcloud2(f, np.zeros((4, 2)), None, None, 0, 'x')
    with pytest.raises(ValueError, match=r'0\.\.255'):
        o.pointcloud2(f, np.zeros((2, 3)), np.full((2, 3), 0.5), None, 0, 'x')
    with pytest.raises(ValueError, match='non-negative'):
        o.pointcloud2(f, np.zeros((2, 3)), None, [1, -1], 0, 'x')
    with pytest.raises(ValueError, match='unknown state'):
        o.pipeline_status(f, 0, 'sleeping', '', 0, 0, 0, '')
    with pytest.raises(ValueError, match='diagnostic level'):
        o.diagnostic_array(f, 0, [{'name': 'x', 'level': 7}])
    with pytest.raises(ValueError, match='together'):
        o.marker_array(f, ROCKS, 0, 'x', vertices=np.zeros((3, 3)))


def test_pointcloud_without_colours_or_labels() -> None:
    from stockpile_ros.ros.typestore import typestore

    f = m.RosbagsFactory(typestore())
    cloud = o.pointcloud2(f, [[1.0, 2.0, 3.0]], None, None, 0, 'x')
    assert cloud.point_step == 12 and [fld.name for fld in cloud.fields] == ['x', 'y', 'z']
    xyz, colors, labels = o.pointcloud2_arrays(cloud)
    assert xyz.tolist() == [[1.0, 2.0, 3.0]] and colors is None and labels is None
    assert o.rock_color(0) == (0.6, 0.6, 0.6) and o.rock_color(3) != o.rock_color(4)
