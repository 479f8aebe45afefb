"""Messages the node set publishes, built from small fake results and serialised with rosbags."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import open3d as o3d
from scipy.spatial.transform import Rotation
from segment_fixtures import small_pile

from stockpile_ros.artefacts import DenseSummary, MeshInfo, OdometryEntry, SparseSummary
from stockpile_ros.camera import Frame
from stockpile_ros.meshio import LabelledMesh, write_labelled_mesh
from stockpile_ros.recon.collector import CollectorState
from stockpile_ros.recon.keyframes import KeyframeStore
from stockpile_ros.ros import topics
from stockpile_ros.ros.messages import RosbagsFactory
from stockpile_ros.ros.publications import (
    keyframe_status,
    reconstruction_diagnostics,
    reconstruction_outputs,
    segmentation_outputs,
)
from stockpile_ros.ros.typestore import typestore
from stockpile_ros.runner import Outcome
from stockpile_ros.segment.pipeline import analyse_mesh

STORE = typestore()
F = RosbagsFactory(STORE)


def _roundtrip(msg: Any) -> Any:
    return STORE.deserialize_cdr(STORE.serialize_cdr(msg, msg.__msgtype__), msg.__msgtype__)


def test_keyframe_status() -> None:
    state = CollectorState(frames=10, keyframes=4, coverage=0.25, decisions={'first': 1})
    topic, msg = keyframe_status(F, 5, state)
    back = _roundtrip(msg)
    assert topic == topics.KEYFRAME_STATUS
    assert (back.keyframes, back.coverage, back.stage) == (4, 0.25, 'keyframes')
    assert '4 keyframes from 10 frames' in back.message


def test_reconstruction_diagnostics_levels() -> None:
    sparse = SparseSummary(9, 10, 0.9, 1, 500, 0.3, 900.0, 'fixed from CameraInfo', [],
                           'sequential', '', 'incremental', ['kf_9.png'], [])  # fmt: skip
    ok = Outcome(True, 'mesh', sparse=sparse, dense=DenseSummary('sgbm-pairs', False, 1000),
                 mesh=MeshInfo(), seconds={'sfm': 1.0, 'dense': 2.0, 'mesh': 3.0})  # fmt: skip
    statuses = [_roundtrip(m).status[0] for _, m in reconstruction_diagnostics(F, 1, ok)]
    assert [s.name for s in statuses] == ['stockpile/sfm', 'stockpile/dense', 'stockpile/mesh']
    assert [s.level for s in statuses] == [0, 0, 1]  # no metric scale: WARN
    assert {kv.key: kv.value for kv in statuses[0].values}['registered'] == '9'
    failed = Outcome(False, 'sfm', 'only 2 of 10 registered', 'Move slower')
    ((topic, msg),) = reconstruction_diagnostics(F, 1, failed)
    status = _roundtrip(msg).status[0]
    assert topic == topics.DIAGNOSTICS
    assert (status.level, status.name, status.message) == (
        2,
        'stockpile/sfm',
        'only 2 of 10 registered',
    )
    assert status.values[0].value == 'Move slower'


def test_segmentation_outputs_carry_every_rock() -> None:
    v, f, _ = small_pile()
    analysis = analyse_mesh(v, f)
    out = dict(segmentation_outputs(F, 7, analysis, 'stockpile', max_faces=10**7))
    assert set(out) == {topics.SEGMENTED_CLOUD, topics.ROCK_MARKERS, topics.ROCKS,
                        topics.GRADATION}  # fmt: skip
    rocks = _roundtrip(out[topics.ROCKS])
    assert len(rocks.rocks) == len(analysis.report.rocks) > 0
    cloud = _roundtrip(out[topics.SEGMENTED_CLOUD])
    assert cloud.width == len(analysis.faces)
    assert [fl.name for fl in cloud.fields] == ['x', 'y', 'z', 'rgb', 'label']
    labels = np.frombuffer(cloud.data.tobytes(), dtype='<u4').reshape(-1, 5)[:, 4]
    assert np.array_equal(labels, analysis.segmentation.labels)
    markers = _roundtrip(out[topics.ROCK_MARKERS]).markers
    assert sum(m.ns == 'rocks' and m.type == 11 for m in markers) == len(rocks.rocks)
    # Over the display limit rocks become boxes.
    small = dict(segmentation_outputs(F, 7, analysis, 'stockpile', max_faces=10))
    boxes = [m for m in small[topics.ROCK_MARKERS].markers if m.ns == 'rocks']
    assert all(m.type == 1 for m in boxes)


def test_reconstruction_outputs_move_the_cloud_and_decimate(tmp_path: Path) -> None:
    (tmp_path / 'dense').mkdir()
    (tmp_path / 'mesh').mkdir()
    pts = np.random.default_rng(0).random((500, 3))
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
    cloud.colors = o3d.utility.Vector3dVector(np.full((500, 3), 0.5))
    o3d.io.write_point_cloud(str(tmp_path / 'dense' / 'dense.ply'), cloud)
    sphere = o3d.geometry.TriangleMesh.create_sphere(1.0, resolution=30)
    faces = np.asarray(sphere.triangles, dtype=np.int64)
    write_labelled_mesh(tmp_path / 'mesh' / 'mesh.ply', LabelledMesh(
        np.asarray(sphere.vertices), faces, np.zeros(len(faces), np.int32), None))  # fmt: skip
    sim = {'scale': 2.0, 'rotation': np.eye(3).ravel().tolist(), 'translation': [0.0, 0.0, 1.0]}
    # Four keyframes whose odometry camera positions are the stockpile ones turned 90 degrees about
    # z and shifted: the stockpile frame must be placed there in the odometry frame.
    store = KeyframeStore(tmp_path / 'keyframes')
    turn = Rotation.from_euler('z', 90, degrees=True)
    shift = np.array([5.0, -1.0, 0.2])
    keyframes = []
    for i, position in enumerate([[0, 0, 1], [1, 0, 1], [1, 1, 1.5], [0, 1, 1.2]]):
        # The camera sits 0.5 m above a base that the fit must not take for it.
        camera = (turn.apply(position) + shift).tolist()
        base = [camera[0], camera[1], camera[2] - 0.5]
        odometry = OdometryEntry(base, [0.0, 0.0, 0.0, 1.0], camera_position=camera)
        frame = Frame(i, np.zeros((4, 4, 3), np.uint8), 'camera_optical_frame', index=i)
        record = store.add(frame, odometry=odometry)
        keyframes.append({'stamp_ns': i, 'file': record.file, 'position': position,
                          'orientation_xyzw': [0.0, 0.0, 0.0, 1.0]})  # fmt: skip
    info = {'model_to_stockpile': sim, 'keyframes': keyframes, 'scale': {'method': 'target'},
            'units': 'm'}  # fmt: skip
    (tmp_path / 'mesh' / 'mesh.json').write_text(json.dumps(info))
    out = dict(reconstruction_outputs(F, 3, tmp_path, 'stockpile', max_faces=1000))
    (placed,) = _roundtrip(out[topics.TF_STATIC]).transforms
    assert (placed.header.frame_id, placed.child_frame_id) == ('odom', 'stockpile')
    t, q = placed.transform.translation, placed.transform.rotation
    assert np.allclose([t.x, t.y, t.z], shift, atol=1e-9)
    assert np.allclose(Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix(), turn.as_matrix())
    dense = _roundtrip(out[topics.DENSE_CLOUD])
    xyz = np.frombuffer(dense.data.tobytes(), dtype='<f4').reshape(-1, 4)[:, :3]
    assert np.allclose(xyz, 2 * pts + [0, 0, 1], atol=1e-5)
    mesh = _roundtrip(out[topics.MESH]).markers[0]
    assert len(faces) > 1000
    assert mesh.type == 11 and 0 < len(mesh.points) <= 3 * 1000
