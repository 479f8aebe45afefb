from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from stockpile_ros.camera import CameraModel, Frame
from stockpile_ros.recon.keyframes import KeyframeSelector, KeyframeStore, SelectorOptions
from stockpile_ros.recon.pipeline import ReconOptions, WorkFolder, run_keyframes


def _texture(seed: int = 0, size: int = 1600) -> np.ndarray:
    rng = np.random.default_rng(seed)
    base = rng.integers(0, 256, (size // 8, size // 8, 3), dtype=np.uint8)
    img = cv2.resize(base, (size, size), interpolation=cv2.INTER_CUBIC)
    return cv2.GaussianBlur(img, (3, 3), 0)


def _view(tex: np.ndarray, shift: float, w: int = 640, h: int = 360) -> np.ndarray:
    """A window into the texture moved ``shift`` pixels to the right (a sideways camera)."""
    m = np.float32([[1, 0, 100 + shift], [0, 1, 100]])
    return cv2.warpAffine(tex, m, (w, h), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP)


def test_blurred_frame_is_rejected_and_sharp_one_kept() -> None:
    tex = _texture()
    sel = KeyframeSelector(SelectorOptions(min_spacing=1, min_parallax=0.05))
    assert sel.push(_view(tex, 0)).reason == 'first'
    for i in range(1, 6):
        sel.push(_view(tex, i))
    blurred = cv2.GaussianBlur(_view(tex, 200), (0, 0), 4)
    d = sel.push(blurred)
    assert not d.accepted and d.reason == 'blurred'
    assert d.sharpness < 0.6 * d.reference
    d = sel.push(_view(tex, 200))
    assert d.accepted and d.reason in ('parallax', 'coverage')


def test_scene_turning_smooth_is_not_blur_but_a_burst_of_blur_is() -> None:
    # The end of a pass: the rocks leave the view for smoother ground, and sharpness falls to 40 %
    # over 20 frames. Then three frames smeared by a bump.
    tex = _texture()
    smooth = cv2.GaussianBlur(tex, (0, 0), 2.5)
    sel = KeyframeSelector(SelectorOptions())
    blurred = []
    for i in range(60):
        w = min(1.0, max(0.0, (i - 20) / 20))
        img = cv2.addWeighted(_view(tex, 4 * i), 1 - w, _view(smooth, 4 * i), w, 0)
        if i in (50, 51, 52):
            img = cv2.GaussianBlur(img, (0, 0), 3)
        if sel.push(img).reason == 'blurred':
            blurred.append(i)
    assert blurred == [50, 51, 52]


def test_parallax_decides_between_frames() -> None:
    tex = _texture(1)
    opts = SelectorOptions(min_spacing=1, min_parallax=0.05, max_spacing=0, work_width=320)
    sel = KeyframeSelector(opts)
    sel.push(_view(tex, 0))
    # 320 px working width, 640 px frames: 0.05 of the width is 32 full-resolution pixels.
    small = sel.push(_view(tex, 12))
    assert not small.accepted and small.reason == 'no-parallax'
    assert small.parallax == pytest.approx(12 / 640, abs=0.004)
    big = sel.push(_view(tex, 40))
    assert big.accepted and big.reason == 'parallax'
    assert big.parallax == pytest.approx(40 / 640, abs=0.005)
    # The reference is now the new keyframe: 10 px further is not enough.
    assert not sel.push(_view(tex, 50)).accepted


def test_spacing_and_bound() -> None:
    tex = _texture(2)
    opts = SelectorOptions(min_spacing=3, min_parallax=0.01, max_keyframes=3)
    sel = KeyframeSelector(opts)
    decisions = [sel.push(_view(tex, 30 * i)) for i in range(12)]
    accepted = [i for i, d in enumerate(decisions) if d.accepted]
    assert accepted == [0, 3, 6]
    assert {d.reason for d in decisions[1:3]} == {'too-close'}
    assert decisions[9].reason == 'limit'


def test_store_writes_as_accepted_and_survives_restart(tmp_path: Path) -> None:
    tex = _texture(3)
    cam = CameraModel.from_fov(640, 360, 60.0)
    store = KeyframeStore(tmp_path / 'keyframes')
    for i in range(3):
        store.add(Frame(i * 1000, _view(tex, 50 * i), 'cam', cam, '/img', i), reason='x')
        # Each line is on disk before the next frame arrives.
        lines = (tmp_path / 'keyframes' / 'keyframes.jsonl').read_text().splitlines()
        assert len(lines) == i + 1
        assert (tmp_path / 'keyframes' / json.loads(lines[-1])['file']).exists()
    # A line cut short by a crash is ignored on reopening.
    with (tmp_path / 'keyframes' / 'keyframes.jsonl').open('a') as f:
        f.write('{"file": "kf_000')
    again = KeyframeStore(tmp_path / 'keyframes')
    assert [r.file for r in again.records] == [r.file for r in store.records]
    assert again.last_index == 2
    assert again.records[0].camera is not None
    np.testing.assert_allclose(again.records[0].camera.k, cam.k)
    np.testing.assert_array_equal(again.image(again.records[1]), _view(tex, 50))


def test_photo_folder_resumes_without_duplicates(tmp_path: Path) -> None:
    tex = _texture(4)
    photos = tmp_path / 'photos'
    photos.mkdir()
    for i in range(5):
        cv2.imwrite(str(photos / f'p{i:02d}.png'), _view(tex, 80 * i))
    work = WorkFolder(tmp_path / 'work')
    first = run_keyframes(photos, work, ReconOptions())
    assert first['keyframes'] == 5 and first['new'] == 5
    again = run_keyframes(photos, work, ReconOptions())
    assert again['keyframes'] == 5 and again['new'] == 0
    # Losing the last keyframe (a crash before its line) only redoes that one.
    lines = (work.keyframes / 'keyframes.jsonl').read_text().splitlines()
    (work.keyframes / 'keyframes.jsonl').write_text('\n'.join(lines[:3]) + '\n')
    redo = run_keyframes(photos, work, ReconOptions())
    assert redo['keyframes'] == 5 and redo['new'] == 2
