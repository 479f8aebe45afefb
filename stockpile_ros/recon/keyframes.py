"""Keyframe selection from a camera stream: sharp frames that add viewpoint, written as accepted.

The selector works on a small grey copy of each frame (about 320 px wide) so that it keeps up with a
camera stream on one core (without poses the fit of the views' motion makes it 34-39 ms a frame,
about 25 fps, in bench/bench_view_angle.py). The copy is levelled to one mean and contrast, so
that a change of exposure reads neither as blur nor as lost corners. Sharpness is the variance of
its Laplacian compared with a running reference (the median of recent frames); corners are
tracked with pyramidal Lucas-Kanade from the last keyframe, and two measures come from them:

- parallax, the median displacement in the image as a share of its width;
- the viewing angle, the median over tracked corners of the angle between the two rays that see
  the corner's scene point, one from each camera centre (what triangulation and SIFT matching
  depend on). Each corner's pixel becomes a ray (CameraInfo intrinsics, or
  ``assumed_hfov_deg``); the rotation between the two views is taken from the camera poses when
  both are known (odometry and the mount's transforms), else from an essential matrix fitted to
  the tracked corners (refined over every tracked pair, see :func:`view_angle_change`); once the
  rays of the current frame are turned back by that rotation, the angle left between each pair
  of rays is the viewing-angle change at that scene point.

Image motion alone misses the viewing-angle change of a camera that turns to keep the pile in
view while it circles it (an orbit): the pile's centre stays put in the image however far the
camera goes round. A 120-rock orbit at 1280x960 kept keyframes about 35 degrees apart that way,
and Structure-from-Motion registered 2 of 10.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, NamedTuple

import cv2
import numpy as np
import numpy.typing as npt
from scipy.optimize import least_squares

from ..artefacts import ArtefactError, KeyframeRecord, OdometryEntry
from ..camera import CameraModel, Frame
from ..ranges import Range

__all__ = [
    'Decision',
    'KeyframeSelector',
    'KeyframeStore',
    'SelectorOptions',
    'view_angle_change',
]


@dataclass(frozen=True)
class SelectorOptions:
    """Tuning of :class:`KeyframeSelector`.

    Attributes:
        work_width: Width [px] of the grey copy every test runs on.
        blur_ratio: A frame is blurred when its sharpness is below this share of the reference
            (a photo of a set: below ``PHOTO_BLUR_SHARE`` of it, see ``run_keyframes``).
        reference_frames: Number of recent frames whose median sharpness is the reference. Short
            enough for the reference to follow the scene: where a pass leaves the pile for plain
            ground, sharpness falls by 40 % within a second, and a 31-frame reference took 28
            sharp frames at the end of a simulated straight pass for blurred (a 0.9 m gap
            between keyframes, where SfM then misregistered two; measured before the copy was
            levelled, which lessens such falls: the tests' scene that turns smooth falls to 0.61
            levelled, to 0.38 not). A burst of a few blurred frames still stands out against 9.
        min_parallax: Median corner displacement, as a share of the image width, that makes a
            frame worth keeping (new ground in view: a pan or a sideways pass).
        view_angle: Viewing-angle change since the last keyframe [deg] (see the module
            documentation) that makes a frame worth keeping.
        max_view_angle: Largest viewing-angle change between two consecutive keyframes [deg],
            whatever the image motion: a frame is kept, even within ``min_spacing``, when the
            next one would pass this bound at the rate the angle grew since the keyframe (a
            rate per frame, so the bound holds at any speed, distance and frame rate, unless the
            next frames are blurred). SfM registered all 41 keyframes of the 120-rock orbit at
            about 9 degrees apart, 2 of 10 at 35.
        assumed_hfov_deg: Horizontal field of view [deg] assumed for the viewing angle when a
            frame comes without CameraInfo. Too wide a guess overstates the angle and keeps
            keyframes closer together (the safe side): 75 against a true 70 keeps them about 10 %
            closer.
        min_tracked: When fewer than this share of the keyframe's corners are still tracked the
            view has changed enough to add coverage, whatever the displacement.
        min_spacing: Fewest frames between two keyframes.
        max_spacing: A sharp frame is kept after this many frames even without parallax, so that
            a slow pass still gets keyframes (0 disables).
        max_keyframes: Upper bound on the number of keyframes.
        max_corners: Corners tracked from each keyframe. The image-only viewing angle needs
            many, not too many: on the orbits of ``bench/bench_view_angle.py`` the tenth
            percentile of its ratio to the true angle was 0.30-0.42 at 100 corners, 0.69-0.75 at
            200, 0.71-0.78 at 300 and 0.44-0.62 at 500 (weaker corners, worse tracks).

    """

    work_width: Annotated[int, Range(32, 4096)] = 320
    blur_ratio: Annotated[float, Range(0.0, 1.0)] = 0.6
    reference_frames: Annotated[int, Range(1, 1000)] = 9
    min_parallax: Annotated[float, Range(0.0, 1.0)] = 0.06
    view_angle: Annotated[float, Range(0.1, 90.0)] = 8.0
    max_view_angle: Annotated[float, Range(0.1, 90.0)] = 12.0
    assumed_hfov_deg: Annotated[float, Range(10.0, 170.0)] = 75.0
    min_tracked: Annotated[float, Range(0.0, 1.0)] = 0.5
    min_spacing: Annotated[int, Range(1, 10000)] = 2
    max_spacing: Annotated[int, Range(0, 100000)] = 60
    max_keyframes: Annotated[int, Range(2, 10000)] = 80
    max_corners: Annotated[int, Range(8, 10000)] = 300


@dataclass(frozen=True)
class Decision:
    """What the selector made of one frame.

    Attributes:
        accepted: Whether the frame became a keyframe.
        reason: Why, in a word or two (``"first"``, ``"view-angle"``, ``"max-angle"``,
            ``"parallax"``, ``"coverage"``, ``"spacing"``, ``"blurred"``, ``"too-close"``,
            ``"no-parallax"``, ``"limit"``).
        sharpness: Variance of the Laplacian of the levelled grey working copy.
        reference: Running reference sharpness it was compared with.
        parallax: Median tracked displacement as a share of the image width (NaN when unknown).
        tracked: Share of the last keyframe's corners still tracked (NaN when unknown).
        view_angle: Viewing-angle change since the last keyframe [deg] (NaN when unknown).
        angle_source: Where the rotation between the views came from: ``"pose"``, ``"image"``
            (essential matrix) or ``""`` (no angle).

    """

    accepted: bool
    reason: str
    sharpness: float
    reference: float
    parallax: float
    tracked: float
    view_angle: float = float('nan')
    angle_source: str = ''


class _Motion(NamedTuple):
    """What tracking the keyframe's corners into a frame gave."""

    parallax: float
    tracked: float
    view_angle: float
    angle_source: str


def _grey_small(image: npt.NDArray[Any], width: int) -> npt.NDArray[np.uint8]:
    """Grey copy of ``image`` at most ``width`` pixels wide (area interpolation)."""
    h, w = image.shape[:2]
    scale = min(1.0, width / w)
    size = (max(1, round(w * scale)), max(1, round(h * scale)))
    # Grey first: area-averaging one channel is cheaper than three (0.8 against 1.4 ms at 720p).
    grey = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY) if image.ndim == 3 else image
    small = cv2.resize(grey, size, interpolation=cv2.INTER_AREA) if scale < 1.0 else grey
    if small.dtype != np.uint8:
        small = cv2.convertScaleAbs(small, alpha=255.0 / max(1.0, float(small.max())))
    return np.ascontiguousarray(small, dtype=np.uint8)


def _levelled(grey: npt.NDArray[np.uint8]) -> npt.NDArray[np.uint8]:
    """Return ``grey`` at mean 128 and standard deviation 40 (saturated to 0-255).

    Sharpness and tracking on it are unchanged by a change of exposure (a gain and an offset over
    the frame). Lucas-Kanade assumes constant brightness: 30 % more gain between a keyframe and a
    frame of a simulated pass lost 35 % of the corners, 64 % once lost tracks are told by their
    residual. The variance of the Laplacian grows with the square of the
    contrast: 40 % darker, the photos of tests/test_photos.py's walks read 0.23-0.47 of their
    median, as blurred as a 1 px Gaussian blur makes them (0.28-0.31); levelled, 0.61-1.44, and
    the 1 px blur 0.34-0.35.
    """
    mean, std = cv2.meanStdDev(grey)
    scale = 40.0 / max(float(std[0, 0]), 1e-6)
    # addWeighted saturates to 0-255 (convertScaleAbs would fold the darkest pixels back up).
    levelled = cv2.addWeighted(grey, scale, grey, 0.0, 128.0 - scale * float(mean[0, 0]))
    return np.asarray(levelled, dtype=np.uint8)


def _rays(
    points: npt.NDArray[np.float32],
    work_shape: tuple[int, ...],
    scale: float,
    camera: CameraModel | None,
    hfov_deg: float,
) -> npt.NDArray[np.float64]:
    """Return unit rays (Nx3, optical frame) of points in the working copy's pixels."""
    pts = points.reshape(-1, 1, 2).astype(np.float64)
    if camera is None:
        height, width = work_shape[:2]
        f = 0.5 * width / np.tan(np.radians(hfov_deg) / 2)
        xy = (pts.reshape(-1, 2) - [(width - 1) / 2, (height - 1) / 2]) / f
    else:
        # The working copy was area-resized: pixel centres map as (x + 0.5) / scale - 0.5.
        full = (pts + 0.5) / scale - 0.5
        d = np.asarray(camera.d, dtype=np.float64).ravel()
        if camera.distortion_model == 'equidistant' and d.size:
            und = cv2.fisheye.undistortPoints(full, camera.k, d[:4])
        else:
            und = cv2.undistortPoints(full, camera.k, d if d.size else None)
        xy = und.reshape(-1, 2)
    rays = np.hstack([xy, np.ones((len(xy), 1))])
    return np.asarray(rays / np.linalg.norm(rays, axis=1, keepdims=True), dtype=np.float64)


# Largest LK residual of a tracked corner, as a share of the keyframe's mean absolute deviation.
LOST_RESIDUAL = 0.9
# RANSAC only starts the refinement: 100 draws read the orbits of bench/bench_view_angle.py as
# well as 1000 (the 1000 allowed took 60 ms a frame at 300 corners, most of the selector's time).
RANSAC_DRAWS = 100
# Two samplers start the refinement; the fit of lower robust cost is kept. From RANSAC's model
# alone the refinement settled in a valley where turn trades for sideways motion on a 6-degree
# orbit step (3.5 degrees of viewing angle read 1.1); MAGSAC's start gets out of it.
STARTS = (cv2.RANSAC, cv2.USAC_MAGSAC)
# Pairs within this many sampler thresholds of the refined model count for the median: tracking
# error grows with a corner's displacement, so a pair one threshold out is as often one with much
# parallax as a bad track (one threshold read the orbits' median angle 11 % shorter than three).
KEEP_THRESHOLDS = 3.0


def _skew(v: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Cross-product matrix of a 3-vector."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def _sampson(
    p1: npt.NDArray[np.float64], p2: npt.NDArray[np.float64], essential: npt.NDArray[np.float64]
) -> npt.NDArray[np.float64]:
    """Signed Sampson distances of homogeneous image points (Nx3, z = 1) to an essential matrix."""
    ex1 = p1 @ essential.T
    etx2 = p2 @ essential
    den = np.sqrt(ex1[:, 0] ** 2 + ex1[:, 1] ** 2 + etx2[:, 0] ** 2 + etx2[:, 1] ** 2)
    return np.asarray(np.sum(p2 * ex1, axis=1) / np.maximum(den, 1e-12), dtype=np.float64)


def _fit_motion(
    p1: npt.NDArray[np.float64], p2: npt.NDArray[np.float64], threshold: float
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]] | None:
    """Rotation and unit translation minimising a robust (Cauchy) Sampson error over all pairs.

    A sampler keeps the model of one minimal sample and its inliers. On a short step over a
    nearly flat pile, corners tracked to a working pixel let a sample trade part of the turn for
    sideways motion: the 12-degree orbit step of the tests read 5.0 and 3.9 degrees of viewing
    angle for 6.9 in two installs, from corners identical up to rounding. The model refined over
    every pair (scale of the loss: ``threshold``) no longer depends on which sample won.

    Args:
        p1: Nx3 homogeneous normalised points (z = 1) in the first view.
        p2: The same points in the second view.
        threshold: Inlier distance of the samplers and scale of the loss (normalised units).

    Returns:
        Rotation and unit translation (``x2 = R x1 + t``), or None when no sampler found a model.

    """

    def residuals(x: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        turn, _ = cv2.Rodrigues(x[:3])
        return _sampson(p1, p2, _skew(x[3:] / np.linalg.norm(x[3:])) @ turn)

    q1 = np.ascontiguousarray(p1[:, :2])
    q2 = np.ascontiguousarray(p2[:, :2])
    best = None
    for method in STARTS:
        # RANSAC draws from OpenCV's per-thread generator: seeded here, the estimate depends on
        # the two frames alone, not on what ran before in the thread (live, each callback may
        # run in another executor thread; unseeded, live and replay kept other keyframes).
        cv2.setRNGSeed(0)
        essential, mask = cv2.findEssentialMat(
            q1,
            q2,
            np.eye(3),
            method=method,
            prob=0.999,
            threshold=threshold,
            maxIters=RANSAC_DRAWS,
        )
        if essential is None or essential.shape[0] < 3 or mask is None:
            continue
        # Up to ten solutions stacked as 3x3 blocks: each starts a refinement.
        for e in essential.reshape(-1, 3, 3):
            _, turn, moved, _ = cv2.recoverPose(e, q1, q2, np.eye(3), mask=mask.copy())
            start, _ = cv2.Rodrigues(turn)
            fit = least_squares(
                residuals,
                np.concatenate([start.ravel(), np.ravel(moved)]),
                loss='cauchy',
                f_scale=threshold,
            )
            if best is None or fit.cost < best.cost:
                best = fit
    if best is None:
        return None
    turn, _ = cv2.Rodrigues(best.x[:3])
    return _in_front(p1, p2, np.asarray(turn, dtype=np.float64), best.x[3:])


def _in_front(
    p1: npt.NDArray[np.float64],
    p2: npt.NDArray[np.float64],
    turn: npt.NDArray[np.float64],
    move: npt.NDArray[np.float64],
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Of the four motions an essential matrix allows, the one with most points in front of both.

    The Sampson error cannot tell ``(R, t)`` from ``-t`` or from the twisted pair (``R`` turned
    half a turn about ``t``): the refinement can end on any of them. On ``stockpile simulate
    --seed 21`` (an arc, no poses offered to the selector) the twisted rotation read the viewing
    angle of the frame after a parallax keyframe as 140 degrees, 9 times, and the selector kept
    those frames as ``max-angle`` keyframes: 19 keyframes in bursts of two to four frames in a
    row, whose depth maps had next to no baseline (10 now). Depths along each ray from
    ``d2 x2 = d1 R x1 + t``.
    """
    move = move / np.linalg.norm(move)
    twist = 2.0 * np.outer(move, move) - np.eye(3)
    best_count, best = -1, (turn, move)
    for r in (turn, twist @ turn):
        for t in (move, -move):
            turned = p1 @ r.T
            across = np.cross(turned, p2)
            norm2 = np.maximum(np.sum(across * across, axis=1), 1e-300)
            d1 = -np.sum(np.cross(t, p2) * across, axis=1) / norm2
            d2 = -np.sum(np.cross(t, turned) * across, axis=1) / norm2
            count = int(np.count_nonzero((d1 > 0) & (d2 > 0)))
            if count > best_count:
                best_count, best = count, (r, t)
    return best


def view_angle_change(
    key_rays: npt.NDArray[np.float64],
    rays: npt.NDArray[np.float64],
    rotation: npt.NDArray[np.float64] | None = None,
    threshold: float = 0.004,
) -> tuple[float, str]:
    """Median viewing-angle change [deg] at scene points seen along paired rays of two views.

    Args:
        key_rays: Nx3 unit rays of the points in the first view (optical frame).
        rays: Nx3 unit rays of the same points in the second view.
        rotation: Rotation from the first view's optical frame to the second's
            (``x2 = R x1 + t``) when the poses are known; None: fitted to the rays (essential
            matrix, refined over every pair by :func:`_fit_motion`).
        threshold: Inlier distance in normalised image units (pixels over focal length): the
            samplers' threshold, the scale of the refinement's robust loss and the Sampson distance
            within which a pair counts for the median.

    Returns:
        The angle and where the rotation came from (``"pose"``, ``"image"``; ``""`` and NaN when
        no essential matrix could be fitted).

    """
    source = 'pose'
    keep = np.ones(len(rays), dtype=bool)
    if rotation is None:
        if len(rays) < 8:
            return float('nan'), ''
        p1 = key_rays / key_rays[:, 2:]
        p2 = rays / rays[:, 2:]
        motion = _fit_motion(p1, p2, threshold)
        if motion is None:
            return float('nan'), ''
        rotation, translation = motion
        keep = np.abs(_sampson(p1, p2, _skew(translation) @ rotation)) < KEEP_THRESHOLDS * threshold
        source = 'image'
        if np.count_nonzero(keep) < 5:
            keep = np.ones(len(rays), dtype=bool)
    turned = key_rays[keep] @ np.asarray(rotation, dtype=np.float64).T
    cosines = np.clip(np.sum(turned * rays[keep], axis=1), -1.0, 1.0)
    return float(np.degrees(np.median(np.arccos(cosines)))), source


class KeyframeSelector:
    """Streaming keyframe selector: ``push`` a frame, learn whether it is a keyframe and why.

    Args:
        options: Thresholds and bounds.

    """

    def __init__(self, options: SelectorOptions | None = None) -> None:
        self.options = options or SelectorOptions()
        self._recent: deque[float] = deque(maxlen=self.options.reference_frames)
        self._key_grey: npt.NDArray[np.uint8] | None = None
        self._key_corners: npt.NDArray[np.float32] | None = None
        self._key_contrast = 0.0
        self._key_orientation: npt.NDArray[np.float64] | None = None
        self._since_key = 0
        self.count = 0

    def reconfigure(self, options: SelectorOptions) -> None:
        """Take new thresholds from the next frame on (the recent sharpness is kept)."""
        self.options = options
        self._recent = deque(self._recent, maxlen=options.reference_frames)

    def resume(
        self,
        last_keyframe: npt.NDArray[np.generic],
        count: int,
        orientation: npt.NDArray[np.float64] | None = None,
    ) -> None:
        """Continue after a restart from the last keyframe written and the number already kept.

        Args:
            last_keyframe: The last keyframe's image.
            count: Keyframes already kept.
            orientation: The last keyframe's camera-to-world rotation, None when unknown.

        """
        self._set_keyframe(_grey_small(last_keyframe, self.options.work_width), orientation)
        self.count = count

    def _set_keyframe(
        self, grey: npt.NDArray[np.uint8], orientation: npt.NDArray[np.float64] | None
    ) -> None:
        corners = cv2.goodFeaturesToTrack(
            grey, maxCorners=self.options.max_corners, qualityLevel=0.01, minDistance=7
        )
        self._key_grey = grey
        self._key_contrast = float(np.mean(np.abs(grey - np.mean(grey))))
        self._key_corners = None if corners is None else corners.astype(np.float32)
        self._key_orientation = orientation
        self._since_key = 0

    def _track(
        self,
        grey: npt.NDArray[np.uint8],
        scale: float,
        camera: CameraModel | None,
        orientation: npt.NDArray[np.float64] | None,
    ) -> _Motion:
        """Parallax, tracked share and viewing angle of ``grey`` against the keyframe."""
        nan = float('nan')
        if self._key_grey is None or self._key_corners is None or len(self._key_corners) < 8:
            return _Motion(nan, nan, nan, '')
        if self._key_grey.shape != grey.shape:
            return _Motion(nan, 0.0, nan, '')
        moved, status, residual = cv2.calcOpticalFlowPyrLK(
            self._key_grey,
            grey,
            self._key_corners,
            np.empty_like(self._key_corners),
            winSize=(13, 13),
            maxLevel=3,
        )
        # A corner whose patch differs from the keyframe's by about as much as unrelated pixels of
        # the keyframe do was not found: LK converges somewhere even on a frame of other content.
        # Its residual (mean absolute difference over the window) against the keyframe's mean
        # absolute deviation: 0.21 at the median and 0.75 at the 95th percentile on the views of
        # bench/bench_view_angle.py, 0.94 at the 1st percentile between frames of random noise.
        ok = (status.ravel() == 1) & (residual.ravel() < LOST_RESIDUAL * self._key_contrast)
        if not np.any(ok):
            return _Motion(nan, 0.0, nan, '')
        start = self._key_corners.reshape(-1, 2)[ok]
        end = moved.reshape(-1, 2)[ok]
        shift = np.linalg.norm(end - start, axis=1)
        parallax = float(np.median(shift)) / grey.shape[1]
        hfov = self.options.assumed_hfov_deg
        if camera is not None and camera.width != round(grey.shape[1] / scale):
            camera = None
        key_rays = _rays(start, grey.shape, scale, camera, hfov)
        rays = _rays(end, grey.shape, scale, camera, hfov)
        rotation = None
        if orientation is not None and self._key_orientation is not None:
            rotation = orientation.T @ self._key_orientation
        focal = 0.5 * grey.shape[1] / np.tan(np.radians(hfov) / 2)
        if camera is not None:
            focal = camera.fx * scale
        # One working pixel of epipolar error: corners tracked at 320 px are good to a fraction.
        angle, source = view_angle_change(key_rays, rays, rotation, threshold=1.0 / focal)
        return _Motion(parallax, float(np.mean(ok)), angle, source)

    def push(
        self,
        image: npt.NDArray[np.generic],
        camera: CameraModel | None = None,
        orientation: npt.NDArray[np.float64] | None = None,
    ) -> Decision:
        """Offer one frame (HxWx3 RGB or HxW grey); returns the decision.

        A blurred frame never becomes a keyframe; a sharp one does when it is the first, when
        the next frame would pass ``max_view_angle`` (even within ``min_spacing``), when its
        viewing angle reached ``view_angle``, when it moved enough from the last keyframe
        (parallax), when most of the last keyframe's corners left the view (coverage) or after
        ``max_spacing`` frames.

        Args:
            image: The frame.
            camera: Its intrinsics (CameraInfo), None: ``assumed_hfov_deg``.
            orientation: Its camera-to-world rotation (the optical frame's, from odometry and
                the mount's transforms) when known at its stamp; None: from the image.

        """
        opt = self.options
        grey = _levelled(_grey_small(image, opt.work_width))
        sharpness = float(cv2.Laplacian(grey, cv2.CV_32F).var())
        reference = float(np.median(self._recent)) if self._recent else sharpness
        self._recent.append(sharpness)
        self._since_key += 1
        nan = float('nan')
        motion = _Motion(nan, nan, nan, '')

        def decide(accepted: bool, reason: str) -> Decision:
            if accepted:
                self._set_keyframe(grey, orientation)
                self.count += 1
            return Decision(accepted, reason, sharpness, reference, *motion)

        if sharpness < opt.blur_ratio * reference:
            return decide(False, 'blurred')
        if self.count >= opt.max_keyframes:
            return decide(False, 'limit')
        if self._key_grey is None:
            return decide(True, 'first')
        motion = self._track(grey, grey.shape[1] / image.shape[1], camera, orientation)
        angle = motion.view_angle
        # The angle grew at this mean rate per frame since the keyframe: the next frame adds as
        # much, whatever the speed, the distance or the frame rate.
        if math.isfinite(angle) and angle * (self._since_key + 1) / self._since_key > (
            opt.max_view_angle
        ):
            return decide(True, 'max-angle')
        if self._since_key < opt.min_spacing:
            return decide(False, 'too-close')
        if math.isfinite(angle) and angle >= opt.view_angle:
            return decide(True, 'view-angle')
        if motion.parallax >= opt.min_parallax:
            return decide(True, 'parallax')
        if motion.tracked < opt.min_tracked:
            return decide(True, 'coverage')
        if opt.max_spacing > 0 and self._since_key >= opt.max_spacing:
            return decide(True, 'spacing')
        return decide(False, 'no-parallax')


class KeyframeStore:
    """The ``keyframes/`` folder: PNGs plus ``keyframes.jsonl``, appended as frames are accepted.

    Each PNG is written to a temporary name and renamed before its line is appended (and flushed),
    so after a crash every line names a complete image.

    Args:
        folder: The ``keyframes/`` folder (created if missing).

    """

    def __init__(self, folder: str | Path) -> None:
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        self.index_path = self.folder / 'keyframes.jsonl'
        self.records: list[KeyframeRecord] = []
        if self.index_path.exists():
            for line in self.index_path.read_text().splitlines():
                # A line cut short by a crash is dropped; its image is rewritten if seen again.
                try:
                    record = KeyframeRecord.from_line(line)
                except (ValueError, KeyError, ArtefactError):
                    continue
                if (self.folder / record.file).exists():
                    self.records.append(record)

    @property
    def last_index(self) -> int:
        """Source index of the last stored keyframe, -1 when empty."""
        return self.records[-1].index if self.records else -1

    def image(self, record: KeyframeRecord) -> npt.NDArray[np.uint8]:
        """Read a stored keyframe back as RGB."""
        bgr = cv2.imread(str(self.folder / record.file), cv2.IMREAD_COLOR)
        if bgr is None:
            raise OSError(f'cannot read {self.folder / record.file}')
        return np.asarray(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), dtype=np.uint8)

    def add(
        self,
        frame: Frame,
        *,
        odometry: OdometryEntry | None = None,
        reason: str = '',
        sharpness: float = 0.0,
    ) -> KeyframeRecord:
        """Write ``frame`` as the next keyframe and append its line."""
        name = f'kf_{len(self.records):05d}_{frame.index:06d}.png'
        image = np.asarray(frame.image)
        if image.ndim == 3:
            image = cv2.cvtColor(image, cv2.COLOR_RGB2BGR)
        tmp = self.folder / f'.{name}.tmp.png'
        if not cv2.imwrite(str(tmp), image):
            raise OSError(f'cannot write {tmp}')
        tmp.replace(self.folder / name)
        record = KeyframeRecord(
            file=name,
            stamp_ns=frame.stamp_ns,
            index=frame.index,
            camera=frame.camera,
            odometry=odometry,
            reason=reason,
            sharpness=sharpness,
        )
        with self.index_path.open('a') as out:
            out.write(record.to_line() + '\n')
            out.flush()
        self.records.append(record)
        return record
