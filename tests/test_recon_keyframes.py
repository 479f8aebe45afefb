from __future__ import annotations

import itertools
import json
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np
import pytest
from recon_synth import look_at, render, scene_mesh, seen_points, viewing_angle

from stockpile_ros.artefacts import WorkFolder
from stockpile_ros.camera import CameraModel, Frame
from stockpile_ros.recon.keyframes import (
    KeyframeSelector,
    KeyframeStore,
    SelectorOptions,
    _in_front,
    view_angle_change,
)
from stockpile_ros.recon.options import ReconOptions
from stockpile_ros.recon.stages import run_keyframes


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
    assert d.accepted and d.reason in ('parallax', 'view-angle', 'coverage')


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


def test_corners_tracked_into_unrelated_noise_are_lost() -> None:
    # LK converges somewhere even between unrelated frames (here independent pixel noise, where
    # it still reported 83-100 % of the corners found): those corners are lost, so the frame has
    # no viewing angle and the keyframe's corners count as gone.
    rng = np.random.default_rng(0)
    sel = KeyframeSelector(SelectorOptions(min_spacing=1, max_spacing=0))
    noise = rng.integers(0, 256, (240, 320, 3), dtype=np.uint8)
    sel.push(noise)
    same = sel.push(np.roll(noise, 3, axis=1))
    assert same.tracked > 0.9 and np.isfinite(same.view_angle)
    other = sel.push(rng.integers(0, 256, (240, 320, 3), dtype=np.uint8))
    assert other.tracked < 0.1 and np.isnan(other.view_angle)
    assert other.accepted and other.reason == 'coverage'


def test_a_change_of_exposure_is_neither_blur_nor_lost_corners() -> None:
    # Auto exposure between a keyframe and a frame: a gain or an offset over the whole frame.
    tex = _texture(4)
    for gain, offset in ((1.3, 0.0), (0.6, 0.0), (1.0, 30.0), (1.0, -30.0)):
        sel = KeyframeSelector(SelectorOptions(min_spacing=1, max_spacing=0))
        sel.push(_view(tex, 0))
        frame = np.clip(_view(tex, 6) * gain + offset, 0, 255).astype(np.uint8)
        decision = sel.push(frame)
        assert decision.reason != 'blurred' and decision.tracked > 0.9, (gain, offset)


def test_spacing_and_bound() -> None:
    tex = _texture(2)
    # The viewing-angle bound, which may take a frame within min_spacing, out of the way.
    opts = SelectorOptions(min_spacing=3, min_parallax=0.01, max_keyframes=3, max_view_angle=90)
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
    assert first.keyframes == 5 and first.new == 5
    again = run_keyframes(photos, work, ReconOptions())
    assert again.keyframes == 5 and again.new == 0
    # Losing the last keyframe (a crash before its line) only redoes that one.
    lines = (work.keyframes / 'keyframes.jsonl').read_text().splitlines()
    (work.keyframes / 'keyframes.jsonl').write_text('\n'.join(lines[:3]) + '\n')
    redo = run_keyframes(photos, work, ReconOptions())
    assert redo.keyframes == 5 and redo.new == 2


@dataclass
class _Orbit:
    """Rendered views of the synthetic rocks from an orbit that keeps the origin in the middle."""

    images: list[np.ndarray]
    centres: list[np.ndarray]
    orientations: list[np.ndarray]
    camera: CameraModel
    points: list[np.ndarray]

    def true_angle(self, a: int, b: int) -> float:
        """Median over the scene points seen by view ``a`` of the angle between the two rays."""
        return viewing_angle(self.points[a], self.centres[a], self.centres[b])


def _orbit_views(steps_deg: np.ndarray, size: tuple[int, int] = (320, 240)) -> _Orbit:
    mesh = scene_mesh()
    cam = CameraModel.from_fov(size[0], size[1], 70.0)
    orbit = _Orbit([], [], [], cam, [])
    for angle in np.radians(steps_deg):
        # Steeply down, so that the 4 m ground fills the view (no corners against the void).
        centre = np.array([1.6 * np.cos(angle), 1.6 * np.sin(angle), 2.0])
        rot, trans = look_at(centre, np.zeros(3))
        orbit.images.append(render(mesh, cam.k, size, rot, trans))
        orbit.centres.append(centre)
        orbit.orientations.append(rot.T)
        orbit.points.append(seen_points(mesh, cam.k, size, rot, centre))
    return orbit


def test_view_angle_between_keyframes_never_passes_the_bound_on_an_orbit() -> None:
    # About 3 degrees of viewing angle per frame, then 6 (faster, or a lower frame rate).
    steps = np.concatenate([np.arange(0, 100, 5.0), np.arange(100, 200, 10.0)])
    orbit = _orbit_views(steps)
    # Image motion out of the way: the viewing-angle rules alone are on trial.
    options = SelectorOptions(blur_ratio=0.0, min_parallax=1.0)

    def gaps(opts: SelectorOptions, with_poses: bool) -> list[float]:
        sel = KeyframeSelector(opts)
        kept = [
            i
            for i, img in enumerate(orbit.images)
            if sel.push(img, orbit.camera, orbit.orientations[i] if with_poses else None).accepted
        ]
        return [orbit.true_angle(a, b) for a, b in itertools.pairwise(kept)]

    # Without them the keyframes drift far apart on this orbit: the bound has work to do.
    unbounded = replace(options, view_angle=90.0, max_view_angle=90.0)
    assert max(gaps(unbounded, with_poses=True)) > 20.0
    with_poses = gaps(options, with_poses=True)
    # Up to the angle's variation over the scene (the bound is a median over tracked corners).
    assert max(with_poses) <= options.max_view_angle + 0.5
    assert min(with_poses) >= 4.0
    # From the images alone the angle is read up to 40 % short (see the next test): the bound
    # holds that much looser, still far from the 35 degrees that broke SfM on an orbit.
    image_only = gaps(options, with_poses=False)
    assert max(image_only) <= 1.5 * options.max_view_angle


def test_image_only_view_angle_is_close_to_the_true_one() -> None:
    orbit = _orbit_views(np.array([0.0, 6.0, 12.0, 18.0]), size=(640, 480))
    never = SelectorOptions(blur_ratio=0.0, view_angle=90.0, max_view_angle=90.0,
                            min_parallax=1.0, min_tracked=0.0, max_spacing=0)  # fmt: skip
    for camera in (orbit.camera, None):
        for k in (1, 2, 3):
            sel = KeyframeSelector(never)
            sel.push(orbit.images[0], camera)
            decision = sel.push(orbit.images[k], camera)
            truth = orbit.true_angle(0, k)
            assert decision.angle_source == 'image'
            # Within 40 %, mostly short: part of the sideways motion is read as a turn (on the
            # orbits of bench/bench_view_angle.py the estimate is 0.80-0.89 of the truth at the
            # median, 0.71-0.78 at the tenth percentile; lines 0.95-1.01).
            assert decision.view_angle == pytest.approx(truth, rel=0.4, abs=0.5), (camera, k)


def test_a_one_frame_step_is_not_read_as_the_twisted_pair() -> None:
    # A cart's step of one frame: 2 cm sideways at 3-5 m, half a degree of turn. The Sampson
    # error cannot tell the true motion from its twisted pair (turned half a turn about the
    # baseline) or from the reversed baseline; only points in front of both views can.
    rng = np.random.default_rng(0)
    scene = rng.uniform([-1.0, -1.0, 3.0], [1.0, 1.0, 5.0], (200, 3))
    c, s = np.cos(np.radians(0.5)), np.sin(np.radians(0.5))
    turn = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    move = np.array([0.02, 0.0, 0.001])
    second = scene @ turn.T + move
    p1, p2 = scene / scene[:, 2:], second / second[:, 2:]
    unit = move / np.linalg.norm(move)
    twisted = (2.0 * np.outer(unit, unit) - np.eye(3)) @ turn
    for r, t in ((turn, move), (twisted, move), (turn, -move), (twisted, -move)):
        got_turn, got_move = _in_front(p1, p2, r, t)
        np.testing.assert_allclose(got_turn, turn, atol=1e-12)
        np.testing.assert_allclose(got_move, unit, atol=1e-12)
    rays1 = p1 / np.linalg.norm(p1, axis=1, keepdims=True)
    rays2 = p2 / np.linalg.norm(p2, axis=1, keepdims=True)
    angle, source = view_angle_change(rays1, rays2, threshold=1e-3)
    true = np.median(np.degrees(np.arccos(np.sum(
        rays1 @ turn.T * rays2, axis=1))))  # fmt: skip
    assert source == 'image' and angle == pytest.approx(true, abs=0.2), (angle, true)
