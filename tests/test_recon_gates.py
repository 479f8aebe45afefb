from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from recon_synth import look_at, orbit, render, scene_mesh

from stockpile_ros.artefacts import WorkFolder
from stockpile_ros.camera import CameraModel, Frame
from stockpile_ros.recon.gates import GateOptions, angular_span, registration_gate
from stockpile_ros.recon.keyframes import KeyframeStore
from stockpile_ros.runner import run_reconstruction
from stockpile_ros.settings import build_settings

NAMES = [f'kf_{i:05d}.png' for i in range(10)]


def _arc(names: list[str], degrees: float) -> dict[str, np.ndarray]:
    angles = np.radians(np.linspace(0, degrees, len(names)))
    return {
        n: np.array([2 * np.cos(a), 2 * np.sin(a), 1.0]) for n, a in zip(names, angles, strict=True)
    }


def test_a_good_model_passes() -> None:
    report = registration_gate(NAMES, [NAMES], centres=_arc(NAMES, 90), pile_centre=np.zeros(3))
    assert report.passed and report.reason == ''
    assert report.share == 1.0 and 75 < (report.span_deg or 0) < 90


def test_split_models_fail_with_the_counts_and_names() -> None:
    models = [NAMES[:6], NAMES[7:]]
    report = registration_gate(NAMES, models, GateOptions(min_registered_share=0.8))
    assert not report.passed
    assert '6 of 10 keyframes registered in one model (60 %, at least 80 % needed)' in report.reason
    assert 'in 2 models (6, 3)' in report.reason
    assert 'model 2: kf_00007.png, kf_00008.png, kf_00009.png' in report.reason
    assert 'in no model: kf_00006.png' in report.reason
    assert report.unregistered == ['kf_00006.png'] and 'overlap' in report.advice
    # Unordered photos: the same gate, its own words.
    photos = registration_gate(NAMES, models, noun='photos')
    assert '6 of 10 photos' in photos.reason


def test_cameras_seeing_the_pile_from_one_side_fail() -> None:
    report = registration_gate(NAMES, [NAMES], centres=_arc(NAMES, 12), pile_centre=np.zeros(3))
    assert not report.passed and report.share == 1.0
    assert 'at most 11 degrees apart (at least 30 needed)' in report.reason
    assert angular_span(np.array([[1.0, 0, 0], [-1.0, 0, 0]]), np.zeros(3)) == 180.0


def test_half_the_keyframes_of_something_else_stop_the_run(tmp_path: Path) -> None:
    """Six views of the pile, then six of another scene: nothing is published from them."""
    cam = CameraModel.from_fov(320, 240, 60.0)
    store = KeyframeStore(WorkFolder(tmp_path).keyframes)
    for part, (mesh, seed) in enumerate([(scene_mesh(0), 0), (scene_mesh(7, rocks=3), 9)]):
        for i, centre in enumerate(orbit(6, arc=0.8)):
            rot, trans = look_at(centre, np.zeros(3))
            image = render(mesh, cam.k, (320, 240), rot, trans, seed=seed)
            index = 6 * part + i
            store.add(Frame(index * 100_000_000, image, 'cam', cam, '/cam', index))
    outcome = run_reconstruction(build_settings({'work_dir': str(tmp_path)}))
    assert not outcome.ok and outcome.stage == 'sfm'
    assert 'of 12 keyframes registered in one model' in outcome.reason
    assert 'overlap' in outcome.advice
    assert outcome.dense is None and not (tmp_path / 'dense').exists()
    gate = json.loads((tmp_path / 'sparse' / 'sparse.json').read_text())['gate']
    assert not gate['passed'] and gate['registered'] <= 7
