from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from recon_synth import look_at, orbit, render, scene_mesh

from stockpile_ros.artefacts import KeyframeRecord, WorkFolder
from stockpile_ros.camera import CameraModel, Frame
from stockpile_ros.errors import CaptureError
from stockpile_ros.recon.keyframes import KeyframeStore
from stockpile_ros.recon.options import ReconOptions
from stockpile_ros.recon.pipeline import reconstruct
from stockpile_ros.recon.sfm import SfmOptions, _shared_camera, load_sparse


def _store(work: WorkFolder, images: list[np.ndarray]) -> None:
    cam = CameraModel.from_fov(images[0].shape[1], images[0].shape[0], 60.0)
    store = KeyframeStore(work.keyframes)
    for i, img in enumerate(images):
        store.add(Frame(i * 100_000_000, img, 'cam', cam, '/cam', i))


@pytest.mark.parametrize('kind', ['textureless', 'blurred'])
def test_unusable_frames_fail_with_reason_and_keep_keyframes(tmp_path: Path, kind: str) -> None:
    rng = np.random.default_rng(0)
    tex = cv2.resize(rng.integers(0, 256, (60, 80, 3), dtype=np.uint8), (640, 480))
    images = []
    for i in range(6):
        if kind == 'textureless':
            img = np.full((240, 320, 3), 120, np.uint8)
            img += rng.integers(0, 2, img.shape, dtype=np.uint8)
        else:
            img = cv2.GaussianBlur(tex[20:260, 10 * i : 10 * i + 320], (0, 0), 12)
        images.append(img)
    work = WorkFolder(tmp_path)
    _store(work, images)
    with pytest.raises(CaptureError) as err:
        reconstruct(None, tmp_path, ReconOptions(), stage='sfm')
    assert err.value.stage == 'sfm'
    assert 'blurred or textureless' in err.value.reason
    assert 'focus' in err.value.advice
    assert len(list(work.keyframes.glob('kf_*.png'))) == 6
    assert len((work.keyframes / 'keyframes.jsonl').read_text().splitlines()) == 6


def test_too_few_keyframes(tmp_path: Path) -> None:
    work = WorkFolder(tmp_path)
    _store(work, [np.zeros((48, 64, 3), np.uint8)] * 2)
    with pytest.raises(CaptureError, match='at least 3'):
        reconstruct(None, tmp_path, ReconOptions(), stage='sfm')


def test_rotation_only_fails_as_degenerate_motion(tmp_path: Path) -> None:
    """A camera turning on the spot sees no parallax: nothing can be triangulated."""
    mesh = scene_mesh()
    cam = CameraModel.from_fov(320, 240, 70.0)
    centre = np.array([2.2, 0.0, 1.3])
    images = []
    for yaw in np.radians(np.linspace(-12, 12, 6)):
        z = np.array([-np.cos(yaw), np.sin(yaw), -0.5])
        z /= np.linalg.norm(z)
        x = np.cross(z, [0.0, 0.0, 1.0])
        x /= np.linalg.norm(x)
        rot = np.stack([x, np.cross(z, x), z])
        images.append(render(mesh, cam.k, (320, 240), rot, -rot @ centre))
    work = WorkFolder(tmp_path)
    _store(work, images)
    with pytest.raises(CaptureError) as err:
        reconstruct(None, tmp_path, ReconOptions(), stage='sfm')
    assert err.value.stage == 'sfm'
    assert 'rotation on the spot' in err.value.reason
    assert 'sideways' in err.value.advice
    assert len(list(work.keyframes.glob('kf_*.png'))) == 6


def test_keyframes_before_the_first_camera_info_share_its_intrinsics() -> None:
    cam = CameraModel.from_fov(320, 240, 60.0)
    other = CameraModel.from_fov(320, 240, 70.0)
    early, late = KeyframeRecord('a.png', 0, 0), KeyframeRecord('b.png', 1, 1, cam)
    assert _shared_camera([early, late, KeyframeRecord('c.png', 2, 2, cam)]) is cam
    assert _shared_camera([early, late, KeyframeRecord('c.png', 2, 2, other)]) is None
    assert _shared_camera([early, KeyframeRecord('c.png', 2, 2)]) is None


def test_a_rerun_gives_the_same_model(tmp_path: Path) -> None:
    """Image numbering, RANSAC and bundle adjustment must not depend on thread timing."""
    mesh = scene_mesh()
    cam = CameraModel.from_fov(320, 240, 70.0)
    images = []
    for centre in orbit(8):
        rot, trans = look_at(centre, np.array([0.0, 0.0, 0.1]))
        images.append(render(mesh, cam.k, (320, 240), rot, trans))
    runs = []
    for name in ('a', 'b'):
        work = WorkFolder(tmp_path / name)
        _store(work, images)
        reconstruct(None, work.root, ReconOptions(sfm=SfmOptions(num_threads=2)), stage='sfm')
        runs.append(load_sparse(work.sparse))
    assert sorted(runs[0].views) == sorted(runs[1].views) and len(runs[0].views) == 8
    for name, view in runs[0].views.items():
        assert np.array_equal(view.center, runs[1].views[name].center)
    assert np.array_equal(runs[0].points, runs[1].points)
    # A camera fixed from CameraInfo has no focal length of its own to doubt.
    sparse = json.loads((tmp_path / 'a' / 'sparse' / 'sparse.json').read_text())
    assert sparse['camera'] == 'fixed from CameraInfo' and sparse['focal_rel_uncertainty'] is None
