from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from stockpile_ros.camera import CameraModel
from stockpile_ros.errors import StockpileError
from stockpile_ros.geometry import umeyama
from stockpile_ros.recon.scale import (
    BarSpec,
    MarkerSpec,
    ScaleEstimate,
    TargetSpec,
    combine,
    detect_charuco,
    detect_markers,
    off_path,
    parse_targets,
    replicate_spread,
    scale_from_markers,
    scale_from_odometry,
    scale_from_target,
)

SPEC = TargetSpec(5, 4, 0.1, 0.075, 'DICT_4X4_50')


def _look_at(centre: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    z = target - centre
    z /= np.linalg.norm(z)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    rot = np.stack([x, np.cross(z, x), z])
    return rot, -rot @ centre


def _board_view(cam: CameraModel, rot: np.ndarray, trans: np.ndarray) -> np.ndarray:
    """Image of the board lying face up on z = 0 seen by a pinhole camera.

    OpenCV boards face -z of their frame: board (x, y) lies at world (x, -y, 0).
    """
    ppm = 2000.0
    size = (
        round(SPEC.squares_x * SPEC.square_length * ppm),
        round(SPEC.squares_y * SPEC.square_length * ppm),
    )
    board = SPEC.board().generateImage(size, marginSize=0)
    pixel_to_board = np.array([[1 / ppm, 0, 0.5 / ppm], [0, 1 / ppm, 0.5 / ppm], [0, 0, 1]])
    h = cam.k @ np.column_stack([rot[:, 0], -rot[:, 1], trans]) @ pixel_to_board
    img = cv2.warpPerspective(
        board, h, (cam.width, cam.height), flags=cv2.INTER_AREA, borderValue=160
    )
    return cv2.cvtColor(img, cv2.COLOR_GRAY2RGB)


def test_target_scale_from_known_cameras() -> None:
    cam = CameraModel.from_fov(960, 540, 60.0)
    centre_of_board = np.array([0.25, -0.2, 0.0])
    s_true = 0.37  # metres per model unit
    detections, poses = {}, {}
    for i, angle in enumerate(np.linspace(-0.5, 0.5, 5)):
        c = centre_of_board + np.array([np.sin(angle), -np.cos(angle), 0.9])
        rot, trans = _look_at(c, centre_of_board)
        ids, px = detect_charuco(_board_view(cam, rot, trans), SPEC)
        assert len(ids) >= 10
        detections[f'v{i}'] = (ids, px)
        # The model is the world shrunk by s_true: same rotations, translations divided by it.
        poses[f'v{i}'] = (cam, rot, trans / s_true)
    est = scale_from_target(detections, poses, SPEC)
    assert est is not None and est.method == 'target'
    assert est.metres_per_unit == pytest.approx(s_true, rel=0.003)
    assert est.rel_uncertainty is not None and 0 < est.rel_uncertainty < 0.01
    assert est.points == (SPEC.squares_x - 1) * (SPEC.squares_y - 1)


def test_target_not_seen_gives_none() -> None:
    cam = CameraModel.from_fov(640, 480, 60.0)
    blank = np.full((480, 640, 3), 128, np.uint8)
    ids, _ = detect_charuco(blank, SPEC)
    assert len(ids) == 0
    poses = {'a': (cam, np.eye(3), np.zeros(3))}
    assert scale_from_target({'a': (ids, np.zeros((0, 2)))}, poses, SPEC) is None


def test_target_spec_parse() -> None:
    assert TargetSpec.parse('charuco:5x4:0.1:0.075:DICT_4X4_50') == SPEC
    assert TargetSpec.parse('charuco:5x4:0.1:0.075').dictionary == 'DICT_4X4_50'
    for bad in (
        'aruco:5x4:0.1:0.075',
        'charuco:5x4:0.1',
        'charuco:5x4:0.1:0.2',
        'charuco:5x4:0.1:0.075:DICT_NOPE',
    ):
        with pytest.raises(StockpileError):
            TargetSpec.parse(bad)


@pytest.mark.parametrize(
    ('text', 'reason'),
    [
        # Each of these parsed before and failed only in the scale stage, after SfM and dense.
        ('charuco:1x1:0.08:0.06', 'at least 2 x 2'),
        ('charuco:5x0:0.08:0.06', 'at least 2 x 2'),
        ('charuco:5x4:inf:0.06', 'finite'),
        ('charuco:5x4:0.08:0.06:CharucoBoard', 'unknown ArUco dictionary CharucoBoard'),
        ('charuco:20x20:0.08:0.06:DICT_4X4_50', '200 markers, DICT_4X4_50 only 50'),
    ],
)
def test_target_specs_opencv_cannot_build_are_refused_when_parsed(text: str, reason: str) -> None:
    with pytest.raises(StockpileError, match=reason):
        TargetSpec.parse(text)


def test_every_parsed_target_spec_builds_its_board() -> None:
    for text in ('charuco:2x2:0.08:0.06', 'charuco:10x10:0.08:0.06:DICT_4X4_50',
                 'charuco:5x4:0.08:0.06:DICT_ARUCO_ORIGINAL'):  # fmt: skip
        spec = TargetSpec.parse(text)
        assert len(spec.corners()) == (spec.squares_x - 1) * (spec.squares_y - 1)


def _rotation(rng: np.random.Generator) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


def test_umeyama_recovers_similarity() -> None:
    rng = np.random.default_rng(0)
    src = rng.normal(size=(20, 3))
    rot = _rotation(rng)
    dst = 2.5 * src @ rot.T + [1.0, 2.0, 3.0]
    sim = umeyama(src, dst)
    assert sim.scale == pytest.approx(2.5)
    np.testing.assert_allclose(sim.rotation, rot, atol=1e-9)
    np.testing.assert_allclose(sim.apply(src), dst, atol=1e-9)


@pytest.mark.parametrize('noise', [0.005, 0.02])
def test_odometry_scale_with_noise(noise: float) -> None:
    rng = np.random.default_rng(1)
    # A cart path: 4 m arc at 1.2 m height, keyframes every 0.5 s, odometry at 30 Hz.
    t_odom = np.arange(0, 10, 1 / 30)
    path = np.column_stack(
        [2.2 * np.cos(t_odom / 6), 2.2 * np.sin(t_odom / 6), np.full_like(t_odom, 1.2)]
    )
    odom = path + rng.normal(0, noise, path.shape)
    stamps = (t_odom * 1e9).astype(np.int64)
    s_true, rot = 0.4, _rotation(rng)
    key_idx = np.arange(5, len(t_odom) - 5, 15)
    centres = {
        int(stamps[i] + 10_000_000): (path[i] - [0.5, 0.0, 0.0]) @ rot / s_true for i in key_idx
    }
    est = scale_from_odometry(centres, stamps, odom)
    assert est is not None and est.method == 'odometry'
    assert est.rel_uncertainty is not None
    err = abs(est.metres_per_unit / s_true - 1)
    # Keyframe stamps are 10 ms after odometry samples: interpolation error stays small.
    assert err < 4 * est.rel_uncertainty + 0.002
    fit = est.parts['fit']
    assert fit is not None and fit < 3 * noise
    assert est.rel_uncertainty == pytest.approx(np.hypot(fit, 0.02))


@pytest.mark.parametrize('seed', range(6))
def test_odometry_calibration_error_is_covered(seed: int) -> None:
    """Wheel odometry 2 % long: the fit alone cannot see it, the stated uncertainty must."""
    rng = np.random.default_rng(seed)
    t_odom = np.arange(0, 10, 1 / 30)
    path = np.column_stack(
        [2.2 * np.cos(t_odom / 6), 2.2 * np.sin(t_odom / 6), np.full_like(t_odom, 1.2)]
    )
    stamps = (t_odom * 1e9).astype(np.int64)
    s_true, rot = 0.4, _rotation(rng)
    odom = path * 1.02 + rng.normal(0, 0.005, path.shape)
    centres = {int(stamps[i]): path[i] @ rot / s_true for i in range(5, len(t_odom) - 5, 15)}
    est = scale_from_odometry(centres, stamps, odom, calibration=0.02)
    assert est is not None and est.rel_uncertainty is not None
    error = abs(est.metres_per_unit / s_true - 1)
    assert error == pytest.approx(0.02, abs=0.004)
    fit = est.parts['fit']
    assert fit is not None and fit < error / 4  # the fit alone would claim far too much
    assert error <= 2 * est.rel_uncertainty  # a 2 sigma interval covers the actual error


def _marker_view(cam: CameraModel, rot: np.ndarray, trans: np.ndarray, size: float) -> np.ndarray:
    """Image of ArUco marker 3 of DICT_4X4_50 (black edge ``size``) face up at the origin."""
    ppm = 4000.0
    side = round(size * ppm)
    page = np.full((2 * side, 2 * side), 255, np.uint8)
    code = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50)
    page[side // 2 : side // 2 + side, side // 2 : side // 2 + side] = (
        cv2.aruco.generateImageMarker(code, 3, side)
    )
    half = side / ppm - 0.5 / ppm
    to_world = np.array([[1 / ppm, 0, -half], [0, -1 / ppm, half], [0, 0, 1]])
    h = cam.k @ np.column_stack([rot[:, 0], rot[:, 1], trans]) @ to_world
    img = cv2.warpPerspective(page, h, (cam.width, cam.height), flags=cv2.INTER_AREA,
                              borderValue=160)  # fmt: skip
    return cv2.cvtColor(img, cv2.COLOR_GRAY2RGB)


def test_marker_scale_from_known_cameras() -> None:
    cam = CameraModel.from_fov(960, 540, 60.0)
    spec = parse_targets('aruco:4x4_50:3:0.2')
    s_true = 0.37
    detections, poses = {}, {}
    for i, angle in enumerate(np.linspace(-0.5, 0.5, 6)):
        c = np.array([np.sin(angle), -np.cos(angle), 0.9])
        rot, trans = _look_at(c, np.zeros(3))
        found = detect_markers(_marker_view(cam, rot, trans, 0.2), ['DICT_4X4_50'])
        assert list(found) == [('DICT_4X4_50', 3)]
        detections[f'v{i}'] = found
        poses[f'v{i}'] = (cam, rot, trans / s_true)
    est = scale_from_markers(detections, poses, [t for t in spec if not isinstance(t, TargetSpec)])
    assert est is not None
    assert est.metres_per_unit == pytest.approx(s_true, rel=0.003)
    assert est.parts['detections'] is not None and est.parts['printed_size'] == 0.0
    # A marker the spec does not name gives nothing.
    other = parse_targets('aruco:DICT_4X4_50:4:0.2')
    assert scale_from_markers(detections, poses, other) is None  # type: ignore[arg-type]


@pytest.mark.parametrize(('blur', 'limit'), [(0.0, 0.02), (1.0, 0.05), (1.5, 0.1)])
def test_marker_corners_are_where_the_edges_meet_blurred_or_not(blur: float, limit: float) -> None:
    # A corner detector pulls a dark square's corners inwards, more the more blurred the image
    # (0.3 % short on sharp renders, 0.85 % at a 1.2 px blur): the scale came out that much
    # too large. Straight edges are not moved by a symmetric blur.
    cam = CameraModel.from_fov(640, 480, 60.0)
    size = 0.1
    world = np.array([[-1, 1, 0], [1, 1, 0], [1, -1, 0], [-1, -1, 0]]) * size / 2
    errors, edges = [], []
    for angle in np.linspace(-0.6, 0.6, 4):
        c = np.array([0.3 * np.sin(angle), -np.cos(angle), 0.8])
        rot, trans = _look_at(c, np.array([0.05, 0.0, 0.0]))
        # Each pixel the mean of 8 x 8 samples, as a sensor's pixel integrates its area.
        to_fine = np.array([[8, 0, 3.5], [0, 8, 3.5], [0, 0, 1]])
        fine = CameraModel(cam.width * 8, cam.height * 8, to_fine @ cam.k, np.zeros(0))
        sharp = _marker_view(fine, rot, trans, size)
        image = cv2.resize(sharp, (cam.width, cam.height), interpolation=cv2.INTER_AREA)
        if blur:
            image = cv2.GaussianBlur(image, (0, 0), blur)
        (quad,) = detect_markers(image, ['DICT_4X4_50']).values()
        cam_pts = world @ rot.T + trans
        truth = (cam_pts @ cam.k.T)[:, :2] / cam_pts[:, 2:]
        errors.append(np.linalg.norm(quad - truth, axis=1).max())
        edges.append(
            np.linalg.norm(np.roll(quad, -1, 0) - quad, axis=1).sum()
            / np.linalg.norm(np.roll(truth, -1, 0) - truth, axis=1).sum()
        )
    # Markers of 60-80 px (cells of 10-13 px): every corner within a few hundredths of a pixel,
    # the edges within 0.05 % on average.
    assert max(errors) < limit, errors
    assert abs(np.mean(edges) - 1) < 0.0005, edges


def test_a_speck_on_the_margin_does_not_move_the_corners() -> None:
    cam = CameraModel.from_fov(640, 480, 60.0)
    rot, trans = _look_at(np.array([-0.06, -0.98, 0.8]), np.array([0.05, 0.0, 0.0]))
    to_fine = np.array([[8, 0, 3.5], [0, 8, 3.5], [0, 0, 1]])
    fine = CameraModel(cam.width * 8, cam.height * 8, to_fine @ cam.k, np.zeros(0))
    image = cv2.resize(_marker_view(fine, rot, trans, 0.1), (cam.width, cam.height),
                       interpolation=cv2.INTER_AREA)  # fmt: skip
    world = np.array([[-1, 1, 0], [1, 1, 0], [1, -1, 0], [-1, -1, 0]]) * 0.05
    cam_pts = world @ rot.T + trans
    truth = (cam_pts @ cam.k.T)[:, :2] / cam_pts[:, 2:]
    # A dark speck on the white just above the top edge, inside the window the edge is fitted in.
    mid = (truth[0] + truth[1]) / 2
    cv2.circle(image, (round(mid[0]), round(mid[1] - 3)), 2, (30, 30, 30), -1)
    (quad,) = detect_markers(image, ['DICT_4X4_50']).values()
    assert np.linalg.norm(quad - truth, axis=1).max() < 0.02


def test_parse_targets() -> None:
    many = parse_targets(
        'aruco:DICT_4X4_50:3:0.15, apriltag:36h11:*:0.1,bar:DICT_5X5_100:1:2:1.0,'
        'charuco:5x4:0.1:0.075'
    )
    assert many[0] == MarkerSpec('DICT_4X4_50', 3, 0.15)
    assert many[1] == MarkerSpec('DICT_APRILTAG_36h11', None, 0.1)
    assert many[2] == BarSpec('DICT_5X5_100', 1, 2, 1.0)
    assert many[3] == SPEC
    assert parse_targets('') == ()
    for bad, why in (
        ('aruco:DICT_4X4_50:50:0.1', 'ids 0 to 49'),
        ('aruco:DICT_NOPE:1:0.1', 'unknown'),
        ('aruco:DICT_4X4_50:1:150', 'outside'),
        ('bar:DICT_4X4_50:1:1:1', 'two different'),
        ('aruco:DICT_4X4_50:1:0.1,aruco:DICT_4X4_50:1:0.2', 'two sizes'),
        ('marker:1', 'expected'),
    ):
        with pytest.raises(StockpileError, match=why):
            parse_targets(bad)


def test_odometry_needs_a_path() -> None:
    stamps = np.arange(10, dtype=np.int64) * 100_000_000
    still = np.zeros((10, 3))
    centres = {int(s): np.random.default_rng(0).normal(size=3) for s in stamps}
    assert scale_from_odometry(centres, stamps, still) is None


def test_off_path_finds_misregistered_keyframes_only() -> None:
    rng = np.random.default_rng(2)
    # Two passes along 4 m at two heights, 40 keyframes; the model is scaled, turned and shifted.
    x = np.concatenate([np.linspace(-2, 2, 20), np.linspace(2, -2, 20)])
    odom = np.column_stack([x, np.full(40, -1.0), np.repeat([1.0, 1.5], 20)])
    rot = _rotation(rng)
    model = (odom + rng.normal(0, 0.01, odom.shape)) @ rot / 0.3 + [3.0, 0.0, 1.0]
    assert not off_path(model, odom, floor=0.2).any()
    # Registered on repeating texture: the last two keyframes land 3 m from where the cart was.
    wrong = model.copy()
    wrong[-2:] += np.array([3.0, 1.0, 0.0]) @ rot / 0.3
    assert np.flatnonzero(off_path(wrong, odom, floor=0.2)).tolist() == [38, 39]
    # When half the path disagrees nothing is singled out.
    half = model.copy()
    half[20:] += np.array([3.0, 1.0, 0.0]) @ rot / 0.3
    assert not off_path(half, odom, floor=0.2).any()


def test_combine() -> None:
    none = combine(None, None)
    assert none.method == 'none' and none.metres_per_unit == 1.0 and none.rel_uncertainty is None
    t = ScaleEstimate('target', 1.00, 0.001, 12)
    o = ScaleEstimate('odometry', 1.03, 0.01, 20)
    assert combine(t, None) is t and combine(None, o) is o
    both = combine(t, o)
    assert both.method == 'target+odometry'
    assert 1.0 < both.metres_per_unit < 1.001
    assert both.rel_uncertainty is not None and both.rel_uncertainty < 0.001
    assert both.note == ''
    # A 3 % disagreement far outside both spreads becomes the uncertainty, with a note.
    sure = combine(t, ScaleEstimate('odometry', 1.03, 0.001, 20))
    assert sure.rel_uncertainty is not None and sure.rel_uncertainty > 0.014
    assert 'disagree' in sure.note


def test_replicate_spread_is_the_scale_carried_to_the_model() -> None:
    """A replicate in other units (its centres k times the model's) with a target k times smaller
    there is the same scale: no spread; targets that differ beyond the units spread by as much."""
    cam = CameraModel.from_fov(640, 480, 60.0)
    poses = {}
    for i in range(6):
        angle = -0.6 + 0.24 * i
        centre = np.array([2.0 * math.cos(angle), 2.0 * math.sin(angle), 1.2 + 0.1 * i])
        rot, trans = _look_at(centre, np.zeros(3))
        poses[f'v{i}'] = (cam, rot, trans)

    def scaled(k: float) -> dict[str, tuple[CameraModel, np.ndarray, np.ndarray]]:
        return {n: (c, rot, k * trans) for n, (c, rot, trans) in poses.items()}

    units = [0.5, 1.0, 2.0, 3.0] * 3
    same = replicate_spread(poses, [scaled(k) for k in units], lambda p: 2.0 / _unit(p, poses))
    assert same == pytest.approx(0.0, abs=1e-9)
    wobble = np.array([-0.01, 0.01] * 6)
    replicates = [scaled(k) for k in units]
    values = iter(wobble)
    spread = replicate_spread(
        poses, replicates, lambda p: 2.0 * math.exp(next(values)) / _unit(p, poses)
    )
    assert spread == pytest.approx(0.01, rel=1e-6)
    # Too few replicates that give a scale: no spread.
    assert replicate_spread(poses, replicates[:5], lambda p: 1.0) is None
    assert replicate_spread(poses, replicates, lambda p: None) is None


def _unit(replicate: dict, poses: dict) -> float:
    """How many replicate units one unit of ``poses`` is (from the first view's distance)."""
    name = next(iter(poses))
    return float(np.linalg.norm(replicate[name][2]) / np.linalg.norm(poses[name][2]))
