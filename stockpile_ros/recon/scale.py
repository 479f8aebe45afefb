"""Metric scale of an SfM model: from a ChArUco target of known size, from odometry, or both.

Target: ChArUco corners are detected in the keyframes, triangulated with the SfM poses (linear,
every view that saw a corner) and fitted to the board's known corner layout with a similarity
(Umeyama); its scale is metres per model unit. Odometry: keyframe centres are fitted the same way to
the odometry positions at the keyframe stamps. Relative uncertainties come from a bootstrap over the
points of each fit. Both are combined by inverse-variance weighting of the log scales.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
import numpy.typing as npt

from ..camera import CameraModel
from ..errors import StockpileError
from ..geometry import umeyama

__all__ = [
    'ScaleEstimate',
    'TargetSpec',
    'bootstrap_scale',
    'combine',
    'detect_charuco',
    'off_path',
    'scale_from_odometry',
    'scale_from_target',
    'triangulate',
]

F64 = npt.NDArray[np.float64]


@dataclass(frozen=True)
class TargetSpec:
    """A ChArUco board.

    Attributes:
        squares_x: Squares along x.
        squares_y: Squares along y.
        square_length: Chessboard square edge [m].
        marker_length: ArUco marker edge [m].
        dictionary: OpenCV dictionary name, e.g. ``"DICT_4X4_50"``.

    """

    squares_x: int
    squares_y: int
    square_length: float
    marker_length: float
    dictionary: str = 'DICT_4X4_50'

    @classmethod
    def parse(cls, text: str) -> TargetSpec:
        """Parse ``charuco:5x4:0.08:0.06[:DICT_4X4_50]`` (squares, square and marker edge [m]).

        Raises:
            StockpileError: The text does not follow that form.

        """
        parts = text.split(':')
        try:
            if parts[0] != 'charuco' or len(parts) not in (4, 5):
                raise ValueError(text)
            sx, sy = (int(v) for v in parts[1].lower().split('x'))
            spec = cls(sx, sy, float(parts[2]), float(parts[3]), *parts[4:5])
        except ValueError:
            raise StockpileError(
                f'target {text!r}: expected charuco:SXxSY:SQUARE_M:MARKER_M[:DICTIONARY], '
                'e.g. charuco:5x4:0.08:0.06:DICT_4X4_50'
            ) from None
        # OpenCV builds no board under 2 x 2 squares; it fails inside the scale stage, after SfM
        # and dense have run, so the spec is refused here.
        if min(spec.squares_x, spec.squares_y) < 2:
            raise StockpileError(f'target {text!r}: a ChArUco board has at least 2 x 2 squares')
        if not all(math.isfinite(v) for v in (spec.square_length, spec.marker_length)):
            raise StockpileError(f'target {text!r}: the square and marker edges must be finite')
        if not 0 < spec.marker_length < spec.square_length:
            raise StockpileError(f'target {text!r}: the marker must be smaller than the square')
        code = getattr(cv2.aruco, spec.dictionary, None)
        if not spec.dictionary.startswith('DICT_') or not isinstance(code, int):
            raise StockpileError(
                f'target {text!r}: unknown ArUco dictionary {spec.dictionary} (a DICT_ name of '
                'cv2.aruco, e.g. DICT_4X4_50 or DICT_5X5_100)'
            )
        # Markers with ids past the dictionary's size can never be detected.
        markers = spec.squares_x * spec.squares_y // 2
        size = len(cv2.aruco.getPredefinedDictionary(code).bytesList)
        if markers > size:
            raise StockpileError(
                f'target {text!r}: the board has {markers} markers, {spec.dictionary} only {size}'
            )
        return spec

    def board(self) -> cv2.aruco.CharucoBoard:
        """Build the OpenCV board object."""
        dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))
        return cv2.aruco.CharucoBoard(
            (self.squares_x, self.squares_y), self.square_length, self.marker_length, dictionary
        )

    def corners(self) -> F64:
        """Nx3 positions of the chessboard corners on the board [m], indexed by ChArUco id."""
        return np.asarray(self.board().getChessboardCorners(), dtype=np.float64).reshape(-1, 3)


@dataclass(frozen=True)
class ScaleEstimate:
    """Metres per model unit.

    Attributes:
        method: ``"target"``, ``"odometry"``, ``"target+odometry"`` or ``"none"``.
        metres_per_unit: The scale (1.0 for ``"none"``).
        rel_uncertainty: Standard deviation relative to the scale, None when unknown.
        points: Number of points the fit used.
        rms_residual: Root mean square residual of the fit [m].
        note: A warning about the estimate, empty when none.

    """

    method: str
    metres_per_unit: float
    rel_uncertainty: float | None
    points: int = 0
    rms_residual: float = 0.0
    note: str = ''


def bootstrap_scale(src: F64, dst: F64, rounds: int = 200, seed: int = 0) -> float | None:
    """Relative standard deviation of the Umeyama scale over bootstrap resamples of the points."""
    n = len(src)
    if n < 4:
        return None
    rng = np.random.default_rng(seed)
    scales = []
    for _ in range(rounds):
        pick = rng.integers(0, n, n)
        if len(np.unique(pick)) < 3:
            continue
        scales.append(umeyama(src[pick], dst[pick]).scale)
    if len(scales) < 10:
        return None
    return float(np.std(scales) / np.median(scales))


def detect_charuco(
    image: npt.NDArray[np.uint8], spec: TargetSpec
) -> tuple[npt.NDArray[np.int64], F64]:
    """ChArUco corner ids and sub-pixel positions (OpenCV pixel convention) in one image."""
    grey = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)
    detector = cv2.aruco.CharucoDetector(spec.board())
    corners, ids, _, _ = detector.detectBoard(grey)
    if ids is None or len(ids) == 0:
        return np.zeros(0, dtype=np.int64), np.zeros((0, 2))
    return np.asarray(ids, dtype=np.int64).ravel(), np.asarray(corners, np.float64).reshape(-1, 2)


def _dlt(rows: list[F64]) -> F64 | None:
    _, _, vt = np.linalg.svd(np.asarray(rows))
    hom = vt[-1]
    if abs(hom[3]) < 1e-12:
        return None
    return np.asarray(hom[:3] / hom[3], dtype=np.float64)


def triangulate(
    observations: Sequence[tuple[CameraModel, F64, F64, F64]],
    max_error_px: float = 2.0,
) -> F64 | None:
    """Linear (DLT) triangulation of one point seen in several views.

    Views where the first estimate lands behind the camera or reprojects farther than
    ``max_error_px`` (a misregistered view, a wrong detection) are dropped and the point is
    triangulated again from the others.

    Args:
        observations: ``(camera, rotation, translation, pixel)`` per view, with the world-to-camera
            pose and the pixel in the OpenCV convention.
        max_error_px: Reprojection error beyond which a view is dropped.

    Returns:
        The point, or None when fewer than two consistent views remain.

    """
    if len(observations) < 2:
        return None
    rows, norms, focal = [], [], []
    for cam, rot, trans, pixel in observations:
        d = np.asarray(cam.d, dtype=np.float64)
        norm = cv2.undistortPoints(pixel.reshape(1, 1, 2), cam.k, d if d.size else None)
        x, y = norm.reshape(2)
        pose = np.hstack([rot, trans.reshape(3, 1)])
        rows.append([x * pose[2] - pose[0], y * pose[2] - pose[1]])
        norms.append((x, y))
        focal.append(cam.fx)
    point = _dlt([r for pair in rows for r in pair])
    if point is None:
        return None
    good = []
    for i, (_, rot, trans, _) in enumerate(observations):
        cam_pt = rot @ point + trans
        if cam_pt[2] <= 0:
            continue
        err = focal[i] * np.hypot(
            cam_pt[0] / cam_pt[2] - norms[i][0], cam_pt[1] / cam_pt[2] - norms[i][1]
        )
        if err <= max_error_px:
            good.append(i)
    if len(good) < 2:
        return None
    if len(good) < len(observations):
        point = _dlt([r for i in good for r in rows[i]])
    return point


def scale_from_target(
    detections: dict[str, tuple[npt.NDArray[np.int64], F64]],
    poses: dict[str, tuple[CameraModel, F64, F64]],
    spec: TargetSpec,
    min_corners: int = 5,
    min_views: int = 3,
) -> ScaleEstimate | None:
    """Scale from ChArUco corners triangulated with the SfM poses.

    Args:
        detections: Corner ids and pixels per keyframe name.
        poses: Camera, world-to-camera rotation and translation per registered keyframe name.
        spec: The board.
        min_corners: Fewest triangulated corners for an estimate (not all on one line).
        min_views: Fewest views a corner must be seen in.

    Returns:
        The estimate, or None when the board was not seen well enough.

    """
    seen: dict[int, list[tuple[CameraModel, F64, F64, F64]]] = {}
    for name, (ids, pixels) in detections.items():
        if name not in poses:
            continue
        cam, rot, trans = poses[name]
        for cid, px in zip(ids, pixels, strict=True):
            seen.setdefault(int(cid), []).append((cam, rot, trans, px))
    layout = spec.corners()
    model_pts, board_pts = [], []
    for cid, obs in sorted(seen.items()):
        if len(obs) < min_views or cid >= len(layout):
            continue
        point = triangulate(obs)
        if point is not None:
            model_pts.append(point)
            board_pts.append(layout[cid])
    if len(model_pts) < min_corners:
        return None
    src, dst = np.asarray(model_pts), np.asarray(board_pts)
    spread = np.linalg.svd(dst - dst.mean(axis=0), compute_uv=False)
    if spread[1] < 0.1 * spread[0]:
        # Corners along one line leave the fit's rotation free about it.
        return None
    # A robust pass: drop corners whose residual is far above the median before the final fit.
    sim = umeyama(src, dst)
    res = np.linalg.norm(sim.apply(src) - dst, axis=1)
    keep = res <= max(3.0 * float(np.median(res)), 1e-9)
    if keep.sum() >= min_corners:
        src, dst = src[keep], dst[keep]
        sim = umeyama(src, dst)
    rms = float(np.sqrt(np.mean(np.sum((sim.apply(src) - dst) ** 2, axis=1))))
    return ScaleEstimate('target', sim.scale, bootstrap_scale(src, dst), len(src), rms)


def _interpolate(
    stamps: npt.NDArray[np.int64], values: F64, at: int, max_gap_ns: int
) -> F64 | None:
    """Linear interpolation of ``values`` at stamp ``at``; None outside or across a big gap."""
    k = int(np.searchsorted(stamps, at))
    if k < len(stamps) and stamps[k] == at:
        return np.asarray(values[k], dtype=np.float64)
    if k == 0 or k == len(stamps) or stamps[k] - stamps[k - 1] > max_gap_ns:
        return None
    w = (at - stamps[k - 1]) / (stamps[k] - stamps[k - 1])
    return np.asarray((1 - w) * values[k - 1] + w * values[k], dtype=np.float64)


def scale_from_odometry(
    centres: dict[int, F64],
    odom_stamps: npt.NDArray[np.int64],
    odom_positions: F64,
    min_points: int = 4,
    max_gap_ns: int = 200_000_000,
) -> ScaleEstimate | None:
    """Scale from keyframe centres (model units) aligned to odometry camera positions [m].

    Args:
        centres: Camera centre in model units per keyframe stamp [ns].
        odom_stamps: Sorted odometry stamps [ns].
        odom_positions: Nx3 camera positions in the odometry frame at those stamps [m].
        min_points: Fewest matched keyframes for an estimate.
        max_gap_ns: Largest odometry gap interpolated across.

    Returns:
        The estimate, or None when too few keyframes match or the path is too short.

    """
    src, dst = [], []
    for stamp, centre in sorted(centres.items()):
        pos = _interpolate(odom_stamps, odom_positions, stamp, max_gap_ns)
        if pos is not None:
            src.append(centre)
            dst.append(pos)
    if len(src) < min_points:
        return None
    s, d = np.asarray(src), np.asarray(dst)
    # A path shorter than a few centimetres (or collinear and tiny) gives no usable scale.
    if np.linalg.norm(d - d.mean(axis=0), axis=1).max() < 0.05:
        return None
    sim = umeyama(s, d)
    rms = float(np.sqrt(np.mean(np.sum((sim.apply(s) - d) ** 2, axis=1))))
    return ScaleEstimate('odometry', sim.scale, bootstrap_scale(s, d), len(s), rms)


def off_path(src: F64, dst: F64, floor: float, min_points: int = 4) -> npt.NDArray[np.bool_]:
    """Keyframes whose centre lies far off the path the others trace, once scaled onto odometry.

    A keyframe that Structure-from-Motion registered on repeating texture (a gravel or ground
    pattern seen twice) can sit metres from where the cart was while every other keyframe is
    right; one such view bends a plain similarity fit of all of them. The fit is redone on the
    keyframes whose residual is under three times their median (or under ``floor``) until the
    set stops changing; a keyframe left out of the last fit is off the path.

    Args:
        src: Nx3 keyframe centres in model units.
        dst: Nx3 odometry camera positions of the same keyframes [m].
        floor: Residual [m] under which a keyframe is never off the path.
        min_points: Fewest keyframes the fit keeps; with fewer nothing is left out.

    Returns:
        Per keyframe, whether it is off the path.

    """
    keep = np.ones(len(src), dtype=bool)
    for _ in range(10):
        sim = umeyama(src[keep], dst[keep])
        res = np.linalg.norm(sim.apply(src) - dst, axis=1)
        inside = res <= max(3.0 * float(np.median(res[keep])), floor)
        if inside.sum() < max(min_points, (len(src) + 1) // 2):
            return np.zeros(len(src), dtype=bool)
        if np.array_equal(inside, keep):
            break
        keep = inside
    return ~keep


def combine(target: ScaleEstimate | None, odometry: ScaleEstimate | None) -> ScaleEstimate:
    """One estimate from whichever is available; inverse-variance weighting when both are."""
    if target is None and odometry is None:
        return ScaleEstimate('none', 1.0, None)
    if target is None or odometry is None:
        only = target if target is not None else odometry
        assert only is not None
        return only
    ut = target.rel_uncertainty if target.rel_uncertainty else None
    uo = odometry.rel_uncertainty if odometry.rel_uncertainty else None
    if ut is None or uo is None:
        # Without both spreads the target, measured against a known length, is trusted.
        return ScaleEstimate(
            'target+odometry',
            target.metres_per_unit,
            ut,
            target.points + odometry.points,
            target.rms_residual,
        )
    wt, wo = 1.0 / ut**2, 1.0 / uo**2
    log_t, log_o = np.log(target.metres_per_unit), np.log(odometry.metres_per_unit)
    log_s = (wt * log_t + wo * log_o) / (wt + wo)
    spread = float(1.0 / np.sqrt(wt + wo))
    gap = abs(float(log_t - log_o))
    note = ''
    if gap > 3.0 * float(np.hypot(ut, uo)):
        # The two disagree beyond their own spreads: some error is systematic (a wrong target
        # size, odometry drift), so the disagreement itself is the honest uncertainty.
        spread = max(spread, gap / 2.0)
        note = f'target and odometry disagree by {100 * gap:.1f} %'
    return ScaleEstimate(
        'target+odometry',
        float(np.exp(log_s)),
        spread,
        target.points + odometry.points,
        max(target.rms_residual, odometry.rms_residual),
        note,
    )
