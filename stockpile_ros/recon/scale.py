"""Metric scale of an SfM model: from printed targets of known size, from odometry, or both.

Targets (:func:`parse_targets`): ChArUco boards, single ArUco or AprilTag markers of a known
black-square edge, every marker of a dictionary at one size, and scale bars (two markers a known
distance apart), several at once. Their corners are detected in the keyframes, triangulated with
the SfM poses (linear, every registered view that saw a corner) and compared with their known
geometry: a board by a similarity fit to its corner layout (uncertainty from a bootstrap over its
corners), markers and bars by the ratio of known to triangulated lengths (uncertainty from the
spread of the detections: leave-one-view-out over the views, and across markers when there are
several), each with the printed size's own tolerance in quadrature. Marker corners are where
lines fitted to the four outer edges meet (:func:`_edge_corners`). What the model adds, the
poses and a self-calibrated focal length that carry a target's scale to the rest of it, is the
spread of the target's scale over copies of the model adjusted again on half of its points
(:func:`replicate_spread`), added in quadrature (the pipeline does).

Odometry: keyframe centres are fitted to the odometry positions at the keyframe stamps; its
uncertainty is the fit's bootstrap spread and the odometry's own calibration uncertainty (a wheel
radius off by 1-2 % scales the whole path and cannot be seen from the fit) in quadrature.
Target and odometry are combined by inverse-variance weighting of the log scales.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TypeAlias

import cv2
import numpy as np
import numpy.typing as npt
from scipy.ndimage import map_coordinates

from ..camera import CameraModel
from ..errors import StockpileError
from ..geometry import umeyama

__all__ = [
    'BarSpec',
    'MarkerDetections',
    'MarkerSpec',
    'ScaleEstimate',
    'Target',
    'TargetSpec',
    'bootstrap_scale',
    'combine',
    'detect_charuco',
    'detect_markers',
    'dictionary_code',
    'marker_scale',
    'off_path',
    'parse_targets',
    'pool_targets',
    'replicate_spread',
    'scale_from_markers',
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

    def text(self) -> str:
        """Return the spec string (as :func:`parse_targets` reads it)."""
        return (
            f'charuco:{self.squares_x}x{self.squares_y}:{self.square_length:g}:'
            f'{self.marker_length:g}:{self.dictionary}'
        )

    def board(self) -> cv2.aruco.CharucoBoard:
        """Build the OpenCV board object."""
        dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))
        return cv2.aruco.CharucoBoard(
            (self.squares_x, self.squares_y), self.square_length, self.marker_length, dictionary
        )

    def corners(self) -> F64:
        """Nx3 positions of the chessboard corners on the board [m], indexed by ChArUco id."""
        return np.asarray(self.board().getChessboardCorners(), dtype=np.float64).reshape(-1, 3)


def dictionary_code(name: str, text: str) -> tuple[str, int]:
    """OpenCV's name and code of an ArUco or AprilTag dictionary, ``DICT_`` prefix optional.

    Args:
        name: As written, e.g. ``DICT_4X4_50``, ``4x4_50`` or ``APRILTAG_36h11``.
        text: The spec it comes from, for the message.

    Raises:
        StockpileError: cv2.aruco has no such dictionary.

    """
    wanted = name.upper() if name.upper().startswith('DICT_') else 'DICT_' + name.upper()
    names = sorted(a for a in dir(cv2.aruco) if a.upper() == wanted and a.startswith('DICT_'))
    codes = [getattr(cv2.aruco, a) for a in names]
    if not names or not isinstance(codes[0], int):
        raise StockpileError(
            f'target {text!r}: unknown marker dictionary {name} (a DICT_ name of cv2.aruco, e.g. '
            'DICT_4X4_50, DICT_6X6_250 or DICT_APRILTAG_36h11)'
        )
    # Both spellings OpenCV offers (DICT_APRILTAG_36H11, DICT_APRILTAG_36h11) are one code.
    chosen = name if name in names else 'DICT_' + name if 'DICT_' + name in names else names[0]
    return chosen, int(codes[0])


def _dictionary_size(code: int) -> int:
    return len(cv2.aruco.getPredefinedDictionary(code).bytesList)


@dataclass(frozen=True)
class MarkerSpec:
    """Single square markers (ArUco or AprilTag) of one dictionary with a known size.

    Attributes:
        dictionary: OpenCV dictionary name, e.g. ``"DICT_4X4_50"`` or ``"DICT_APRILTAG_36h11"``.
        marker_id: The marker's id; None for every marker of the dictionary.
        size: Edge of the black square (the marker's outer border) [m].

    """

    dictionary: str
    marker_id: int | None
    size: float

    def text(self) -> str:
        """Return the spec string (as :func:`parse_targets` reads it)."""
        mark = '*' if self.marker_id is None else str(self.marker_id)
        return f'aruco:{self.dictionary}:{mark}:{self.size:g}'


@dataclass(frozen=True)
class BarSpec:
    """A scale bar: two markers of one dictionary whose centres lie a known distance apart.

    Attributes:
        dictionary: OpenCV dictionary name.
        first: Id of one marker.
        second: Id of the other.
        distance: Distance between the two markers' centres [m].

    """

    dictionary: str
    first: int
    second: int
    distance: float

    def text(self) -> str:
        """Return the spec string (as :func:`parse_targets` reads it)."""
        return f'bar:{self.dictionary}:{self.first}:{self.second}:{self.distance:g}'


Target: TypeAlias = TargetSpec | MarkerSpec | BarSpec
"""One scale target of a spec string."""

_TARGET_FORMS = (
    'aruco:DICT:ID:SIZE_M, aruco:DICT:*:SIZE_M, apriltag:36h11:ID:SIZE_M, '
    'bar:DICT:ID1:ID2:DIST_M or charuco:SXxSY:SQUARE_M:MARKER_M[:DICT], several joined by commas'
)


def _length(value: str, what: str, text: str) -> float:
    try:
        length = float(value)
    except ValueError:
        raise StockpileError(f'target {text!r}: {what} {value!r} is not a number') from None
    # Anything from a 1 cm tag to a 100 m survey bar; outside that it is a typo (mm for m).
    if not 0.01 <= length <= 100.0:
        raise StockpileError(f'target {text!r}: {what} {value} m is outside [0.01, 100] m')
    return length


def _marker_id(value: str, code: int, dictionary: str, text: str) -> int:
    if not value.isdigit():
        raise StockpileError(f'target {text!r}: marker id {value!r} is not a whole number')
    size = _dictionary_size(code)
    if int(value) >= size:
        raise StockpileError(f'target {text!r}: {dictionary} has ids 0 to {size - 1} only')
    return int(value)


def _parse_one(text: str) -> Target:
    parts = text.split(':')
    kind = parts[0].lower()
    if kind == 'charuco':
        return TargetSpec.parse(text)
    if kind in ('aruco', 'apriltag') and len(parts) == 4:
        name = parts[1] if kind == 'aruco' else f'APRILTAG_{parts[1]}'
        dictionary, code = dictionary_code(name, text)
        marker = None if parts[2] == '*' else _marker_id(parts[2], code, dictionary, text)
        return MarkerSpec(dictionary, marker, _length(parts[3], 'marker size', text))
    if kind == 'bar' and len(parts) == 5:
        dictionary, code = dictionary_code(parts[1], text)
        first = _marker_id(parts[2], code, dictionary, text)
        second = _marker_id(parts[3], code, dictionary, text)
        if first == second:
            raise StockpileError(f'target {text!r}: a bar needs two different markers')
        return BarSpec(dictionary, first, second, _length(parts[4], 'bar length', text))
    raise StockpileError(f'target {text!r}: expected {_TARGET_FORMS}')


def parse_targets(text: str) -> tuple[Target, ...]:
    """Parse a target spec string: one or more targets joined by commas ('' gives none).

    Forms: ``aruco:DICT:ID:SIZE_M`` (one marker, its black square's edge in metres),
    ``aruco:DICT:*:SIZE_M`` (every marker of the dictionary, one size),
    ``apriltag:FAMILY:ID:SIZE_M`` (the same as ``aruco:DICT_APRILTAG_FAMILY:...``),
    ``bar:DICT:ID1:ID2:DIST_M`` (two markers whose centres are DIST_M apart) and
    ``charuco:SXxSY:SQUARE_M:MARKER_M[:DICT]``.

    Raises:
        StockpileError: A part does not follow those forms, names an unknown dictionary or an id
            past its end, or the same marker twice with different sizes.

    """
    targets = tuple(_parse_one(part.strip()) for part in text.split(',') if part.strip())
    sizes: dict[tuple[str, int | None], float] = {}
    for target in targets:
        if isinstance(target, MarkerSpec):
            key = (target.dictionary, target.marker_id)
            if sizes.setdefault(key, target.size) != target.size:
                raise StockpileError(f'target {text!r}: {target.text()} is given two sizes')
    return targets


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
        parts: The relative uncertainties ``rel_uncertainty`` is made of, by name (``fit`` and
            ``calibration`` for odometry; ``detections``, ``markers`` and ``printed_size`` for
            markers; ``model`` added to a target's, what the poses and the focal length add,
            see :func:`replicate_spread`, or ``focal`` in its place where no re-adjusted copies
            of the model could be made, see :func:`stockpile_ros.recon.sfm.focal_uncertainty`;
            ``target`` and ``odometry`` when both are combined).

    """

    method: str
    metres_per_unit: float
    rel_uncertainty: float | None
    points: int = 0
    rms_residual: float = 0.0
    note: str = ''
    parts: dict[str, float | None] = field(default_factory=dict)


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
    detections: Mapping[str, tuple[npt.NDArray[np.int64], F64]],
    poses: Mapping[str, tuple[CameraModel, F64, F64]],
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


MarkerDetections: TypeAlias = dict[tuple[str, int], F64]
"""Marker corners in one image: 4x2 pixels (OpenCV order and convention) by (dictionary, id)."""


def _edge_corners(grey: F64, quad: F64, cells: int) -> F64 | None:
    """Corners of a marker where straight lines fitted to its four outer edges meet.

    A corner detector (``cv2.cornerSubPix``) puts an L-shaped corner of a dark square where the
    grey levels round it balance, and any blur (focus, motion, a codec, the pixels' own area)
    pulls that point into the square: on rendered markers 60 px wide the edges came out 0.3 %
    short, 0.85 % under a 1.2 px blur, and the scale that much too large. A straight edge is not
    moved by a symmetric blur: along each normal of an edge the share of paper grey integrated
    over a window gives the edge's offset whatever the blur's width (for a step from ink level
    ``d`` to paper level ``p`` seen through a unit-area blur, the integral of ``(I - d) / (p - d)``
    over ``[-r, r]`` is ``r - offset``). The window is under half a cell either side, so it sees
    the black border and the white margin only, and samples stay a cell away from the corners.
    That holds while the blur's spread is well under half a cell (a marker of 60 px with 6 cells
    across: a blur of 1.5 px); a coarser blur still leaves the edges nearer than the corners.

    Args:
        grey: The image, one channel, as float.
        quad: 4x2 first corners (OpenCV order), within about a pixel.
        cells: Cells across the marker, its black border included.

    Returns:
        The refined 4x2 corners, or None when an edge shows no ink-to-paper step.

    """
    centre = quad.mean(axis=0)
    lines = []
    for i in range(4):
        start, end = quad[i], quad[(i + 1) % 4]
        length = float(np.linalg.norm(end - start))
        along = (end - start) / length
        normal = np.array([along[1], -along[0]])
        if normal @ ((start + end) / 2 - centre) < 0:
            normal = -normal  # outward, towards the paper
        cell = length / cells
        # Across the edge a cell is as long as the neighbouring edges' cells: a marker seen
        # obliquely is foreshortened across one pair of edges.
        across = (np.linalg.norm(quad[i - 1] - start) + np.linalg.norm(quad[(i + 2) % 4] - end)) / 2
        reach = 0.45 * float(across) / cells
        # About two samples a pixel along the edge, an eighth of a pixel across it.
        ts = np.linspace(cell, length - cell, max(8, round(2 * (length - 2 * cell))))
        offsets = np.linspace(-reach, reach, max(9, round(16 * reach) | 1))
        base = start + np.outer(ts, along)
        points = base[:, None, :] + offsets[None, :, None] * normal
        values = map_coordinates(grey, [points[..., 1].ravel(), points[..., 0].ravel()],
                                 order=1, mode='nearest').reshape(points.shape[:2])  # fmt: skip
        ink, paper = float(np.median(values[:, 0])), float(np.median(values[:, -1]))
        if paper <= ink:
            return None
        share = np.clip((values - ink) / (paper - ink), 0.0, 1.0)
        step = offsets[1] - offsets[0]
        offset = reach - (share[:, :-1] + share[:, 1:]).sum(axis=1) * step / 2
        edge = base + offset[:, None] * normal
        for _ in range(2):
            # The second fit leaves out points far off the first line (a shadow or a speck on
            # the margin): beyond three robust standard deviations.
            mean = edge.mean(axis=0)
            direction = np.linalg.svd(edge - mean)[2][0]
            perpendicular = np.array([-direction[1], direction[0]])
            residual = np.abs((edge - mean) @ perpendicular)
            keep = residual <= 3 * 1.4826 * float(np.median(residual)) + 1e-9
            if keep.sum() < len(edge) // 2:
                break
            edge = edge[keep]
        lines.append((perpendicular, float(perpendicular @ mean)))
    corners = np.array([
        np.linalg.solve(np.array([lines[i - 1][0], lines[i][0]]),
                        np.array([lines[i - 1][1], lines[i][1]]))
        for i in range(4)
    ])  # fmt: skip
    # The window reaches under half a cell: a corner that moved farther is a failed fit.
    cell = float(np.mean(np.linalg.norm(np.roll(quad, -1, axis=0) - quad, axis=1))) / cells
    if not np.all(np.linalg.norm(corners - quad, axis=1) <= cell):
        return None
    return np.asarray(corners, dtype=np.float64)


def detect_markers(image: npt.NDArray[np.uint8], dictionaries: Sequence[str]) -> MarkerDetections:
    """Corners of the markers of ``dictionaries`` in one image, refined to sub-pixel.

    Corners are refined by fitting the four outer edges (:func:`_edge_corners`, twice: the
    second pass starts from the first's corners), where that fails by ``cv2.cornerSubPix``.
    A marker id found twice in one image (two prints of one id) is left out: which corner
    belongs to which print cannot be told.
    """
    grey = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)
    levels = grey.astype(np.float64)
    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    out: MarkerDetections = {}
    for name in dict.fromkeys(dictionaries):
        code = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, name))
        detector = cv2.aruco.ArucoDetector(code, params)
        corners, ids, _ = detector.detectMarkers(grey)
        if ids is None:
            continue
        cells = code.markerSize + 2 * params.markerBorderBits
        found = [int(i) for i in np.asarray(ids).ravel()]
        for marker, quad in zip(found, corners, strict=True):
            if found.count(marker) != 1:
                continue
            first = np.asarray(quad, dtype=np.float64).reshape(4, 2)
            refined = _edge_corners(levels, first, cells)
            if refined is not None:
                refined = _edge_corners(levels, refined, cells)
            out[(name, marker)] = first if refined is None else refined
    return out


_Poses = Mapping[str, tuple[CameraModel, F64, F64]]


def _marker_corners(
    detections: Mapping[str, MarkerDetections], poses: _Poses, min_views: int, leave_out: str
) -> dict[tuple[str, int], F64]:
    """Triangulated 4x3 corners of each marker whose four corners were all triangulated."""
    seen: dict[tuple[str, int], list[list[tuple[CameraModel, F64, F64, F64]]]] = {}
    for name, markers in detections.items():
        if name not in poses or name == leave_out:
            continue
        cam, rot, trans = poses[name]
        for key, quad in markers.items():
            views = seen.setdefault(key, [[], [], [], []])
            for corner in range(4):
                views[corner].append((cam, rot, trans, quad[corner]))
    out = {}
    for key, views in seen.items():
        if len(views[0]) < min_views:
            continue
        points = [triangulate(obs) for obs in views]
        if all(p is not None for p in points):
            out[key] = np.array(points, dtype=np.float64)
    return out


# Edges, then diagonals, of a marker's four corners (OpenCV's clockwise order).
_PAIRS = ((0, 1), (1, 2), (2, 3), (3, 0), (0, 2), (1, 3))
_FACTORS = np.array([1.0, 1.0, 1.0, 1.0, math.sqrt(2.0), math.sqrt(2.0)])

# A marker whose six lengths disagree by more than this (relative std) is not a flat square in
# the model: a corner on the wrong spot, a bent print. It is left out of the scale.
_MAX_SHAPE_SPREAD = 0.05


def _marker_lengths(
    corners: Mapping[tuple[str, int], F64], specs: Sequence[MarkerSpec | BarSpec]
) -> tuple[dict[str, tuple[F64, F64]], list[str]]:
    """Known [m] and model lengths per target unit (a marker or a bar), and rejected markers."""
    sizes = {(s.dictionary, s.marker_id): s.size for s in specs if isinstance(s, MarkerSpec)}
    units: dict[str, tuple[F64, F64]] = {}
    rejected = []
    for (name, marker), quad in sorted(corners.items()):
        size = sizes.get((name, marker), sizes.get((name, None)))
        if size is None:
            continue
        model = np.array([np.linalg.norm(quad[i] - quad[j]) for i, j in _PAIRS])
        ratios = size * _FACTORS / np.maximum(model, 1e-12)
        if np.std(ratios) > _MAX_SHAPE_SPREAD * np.mean(ratios):
            rejected.append(f'{name}:{marker}')
            continue
        units[f'{name}:{marker}'] = (size * _FACTORS, model)
    for spec in specs:
        if isinstance(spec, BarSpec):
            ends = [corners.get((spec.dictionary, m)) for m in (spec.first, spec.second)]
            if ends[0] is not None and ends[1] is not None:
                model_length = float(np.linalg.norm(ends[0].mean(axis=0) - ends[1].mean(axis=0)))
                units[spec.text()] = (np.array([spec.distance]), np.array([model_length]))
    return units, rejected


def _log_scale(units: Mapping[str, tuple[F64, F64]]) -> tuple[float, dict[str, float]]:
    """Weighted mean log scale over the units and each unit's log scale.

    A unit's relative error goes as corner noise over its length, so each weighs as its mean
    model length squared: a 1 m bar counts more than a 10 cm marker.
    """
    logs = {u: math.log(float(k.sum() / m.sum())) for u, (k, m) in units.items()}
    weights = {u: float(np.mean(m)) ** 2 for u, (_, m) in units.items()}
    total = sum(weights.values())
    return sum(weights[u] * logs[u] for u in logs) / total, logs


def marker_scale(
    detections: Mapping[str, MarkerDetections],
    poses: _Poses,
    specs: Sequence[MarkerSpec | BarSpec],
    *,
    min_views: int = 3,
) -> float | None:
    """Return the scale :func:`scale_from_markers` gives, without its uncertainty (or None)."""
    units, _ = _marker_lengths(_marker_corners(detections, poses, min_views, ''), specs)
    return math.exp(_log_scale(units)[0]) if units else None


def replicate_spread(
    poses: _Poses,
    replicates: Sequence[_Poses],
    scale: Callable[[_Poses], float | None],
    min_rounds: int = 10,
) -> float | None:
    """Relative spread of a target's scale of the model over re-adjusted copies of the model.

    A target fixes the scale where it lies; the poses and the focal length carry it to the rest
    of the model, and they are only as good as bundle adjustment made them. Each replicate
    (:func:`stockpile_ros.recon.sfm.resampled_poses`: the model adjusted again on half of its
    points) has units of its own: its camera centres, fitted onto the model's by a similarity,
    say how many of its units one model unit is, and the target's scale in the replicate times
    that is again metres per model unit. The spread of that about its mean over the replicates
    (delete-half jackknife) is the part of the scale's uncertainty the model adds: the focal
    length's and the poses' together, with however the scale depends on them.

    Args:
        poses: The model's cameras and poses.
        replicates: The re-adjusted copies.
        scale: Metres per unit of a set of poses (the target's estimate), None when none.
        min_rounds: Fewest replicates that must give a scale.

    Returns:
        The relative standard deviation, None with fewer usable replicates.

    """
    centres = {n: -rot.T @ trans for n, (_, rot, trans) in poses.items()}
    logs = []
    for replicate in replicates:
        names = sorted(n for n in centres if n in replicate)
        value = scale(replicate) if len(names) >= 3 else None
        if value is None or not value > 0:
            continue
        src = np.array([centres[n] for n in names])
        dst = np.array([-replicate[n][1].T @ replicate[n][2] for n in names])
        logs.append(math.log(value * umeyama(src, dst).scale))
    if len(logs) < min_rounds:
        return None
    return float(np.sqrt(np.mean((np.asarray(logs) - np.mean(logs)) ** 2)))


def scale_from_markers(
    detections: Mapping[str, MarkerDetections],
    poses: _Poses,
    specs: Sequence[MarkerSpec | BarSpec],
    *,
    min_views: int = 3,
    size_uncertainty: float = 0.0,
) -> ScaleEstimate | None:
    """Scale from markers and scale bars of known size, triangulated with the SfM poses.

    Each marker seen in at least ``min_views`` registered views gets its four corners
    triangulated; its four edges and two diagonals against the known size give its scale, a bar
    the distance between its two markers' centres. The estimate is the weighted mean over them.
    Its uncertainty comes from the detections: the leave-one-view-out (jackknife) spread of the
    estimate and, with several markers or bars, their spread over the square root of their
    number, whichever is larger; ``size_uncertainty`` (how well the printed size is known) is
    added in quadrature.

    Args:
        detections: Marker corners per keyframe name (:func:`detect_markers`).
        poses: Camera, world-to-camera rotation and translation per registered keyframe name.
        specs: The markers and bars.
        min_views: Fewest views a marker must be seen in.
        size_uncertainty: Relative uncertainty of the printed sizes.

    Returns:
        The estimate, or None when no marker or bar was seen well enough.

    """
    corners = _marker_corners(detections, poses, min_views, '')
    units, rejected = _marker_lengths(corners, specs)
    if not units:
        return None
    log_s, logs = _log_scale(units)
    scale = math.exp(log_s)
    # Leave each view out in turn: how much the estimate rests on any one view's detections.
    replicates = []
    for name in sorted(n for n in detections if n in poses and detections[n]):
        again, _ = _marker_lengths(_marker_corners(detections, poses, min_views, name), specs)
        if set(again) == set(units):
            replicates.append(_log_scale(again)[0])
    n = len(replicates)
    jackknife = None
    if n >= 3:
        mean = float(np.mean(replicates))
        jackknife = math.sqrt((n - 1) / n * sum((r - mean) ** 2 for r in replicates))
    spread = None
    if len(logs) >= 2:
        spread = float(np.std(list(logs.values()), ddof=1)) / math.sqrt(len(logs))
    known = [d for d in (jackknife, spread) if d is not None]
    detection = max(known) if known else None
    rel = None if detection is None else math.hypot(detection, size_uncertainty)
    residuals = np.concatenate([scale * m - k for k, m in units.values()])
    note = f'markers not square in the model, left out: {", ".join(rejected)}' if rejected else ''
    return ScaleEstimate(
        'target', scale, rel, 4 * len(corners), float(np.sqrt(np.mean(residuals**2))), note,
        {'detections': jackknife, 'markers': spread, 'printed_size': size_uncertainty},
    )  # fmt: skip


def pool_targets(estimates: Mapping[str, ScaleEstimate]) -> ScaleEstimate | None:
    """One target estimate from several (boards, markers) by inverse-variance weights.

    Estimates without an uncertainty are left out when some have one.
    """
    if len(estimates) <= 1:
        return next(iter(estimates.values()), None)
    sure = {k: e for k, e in estimates.items() if e.rel_uncertainty}
    chosen = sure or dict(estimates)
    weights = {
        k: 1.0 / e.rel_uncertainty**2 if e.rel_uncertainty else 1.0 for k, e in chosen.items()
    }
    total = sum(weights.values())
    log_s = sum(w * math.log(chosen[k].metres_per_unit) for k, w in weights.items()) / total
    return ScaleEstimate(
        'target', math.exp(log_s), 1.0 / math.sqrt(total) if sure else None,
        sum(e.points for e in chosen.values()), max(e.rms_residual for e in chosen.values()),
        '; '.join(e.note for e in chosen.values() if e.note),
        {k: e.rel_uncertainty for k, e in chosen.items()},
    )  # fmt: skip


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
    calibration: float = 0.02,
) -> ScaleEstimate | None:
    """Scale from keyframe centres (model units) aligned to odometry camera positions [m].

    The fit's own spread (bootstrap) only says how well the two paths agree in shape; a scale
    error of the odometry itself (wheel radius, tyre pressure, slip) stretches the odometry path
    as a whole and leaves no residual. ``calibration`` is that error's relative standard
    deviation, added in quadrature.

    Args:
        centres: Camera centre in model units per keyframe stamp [ns].
        odom_stamps: Sorted odometry stamps [ns].
        odom_positions: Nx3 camera positions in the odometry frame at those stamps [m].
        min_points: Fewest matched keyframes for an estimate.
        max_gap_ns: Largest odometry gap interpolated across.
        calibration: Relative uncertainty of the odometry's own scale.

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
    fit = bootstrap_scale(s, d)
    rel = math.hypot(fit or 0.0, calibration) if fit is not None or calibration > 0 else None
    return ScaleEstimate(
        'odometry', sim.scale, rel, len(s), rms, parts={'fit': fit, 'calibration': calibration}
    )


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
            parts={'target': ut, 'odometry': uo},
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
        {'target': ut, 'odometry': uo},
    )
