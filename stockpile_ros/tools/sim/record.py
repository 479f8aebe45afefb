"""Drive the cart past the scene, render every frame and write the bag and its truth folder.

Topics (REP 105 frames):
- ``/camera/image_raw`` (``sensor_msgs/Image``, rgb8) or ``/camera/image_raw/compressed``
  (``sensor_msgs/CompressedImage``, JPEG), and ``/camera/camera_info``; frame
  ``camera_optical_frame``;
- ``/odom`` (``nav_msgs/Odometry``, ``odom`` -> ``base_link``), wheel odometry with optional drift;
- ``/tf``: ``odom`` -> ``base_link`` at every odometry message, plus ``base_link`` ->
  ``camera_link`` when the mast changes height (two-height paths);
- ``/tf_static``: ``camera_link`` -> ``camera_optical_frame``, and ``base_link`` -> ``camera_link``
  for single-height paths.
"""

from __future__ import annotations

import shutil
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt

from ...artefacts import to_json
from ...bagio.writer import BagWriter
from ...camera import CameraModel
from ...errors import StockpileError
from ...progress import progress
from ...ros import messages as m
from ...segment.gradation import gradation
from .camera_path import OPTICAL_IN_LINK, CartPath, PathConfig, auto_distance, quat_from_matrix
from .render import Lighting, Renderer, linear_to_srgb
from .scene import Scene, SceneConfig, build_scene
from .truth import (
    DIMENSION_METHOD,
    SPECIFIC_GRAVITY,
    TRUTH_SCHEMA,
    VisibilityAccumulator,
    rock_truth,
    scene_mesh,
    write_truth,
)

__all__ = [
    'IMAGE_TOPIC',
    'INFO_TOPIC',
    'ODOM_TOPIC',
    'SimulationConfig',
    'SimulationSummary',
    'finish_image',
    'motion_blur',
    'odometry_track',
    'simulate',
    'truth_folder',
]

IMAGE_TOPIC = '/camera/image_raw'
INFO_TOPIC = '/camera/camera_info'
ODOM_TOPIC = '/odom'
START_NS = 1_700_000_000_000_000_000
GROUND_HALF = 60.0


@dataclass(frozen=True)
class SimulationConfig:
    """Everything that defines a simulated recording.

    Attributes:
        seed: Seed of every random choice.
        scene: The scene.
        path: The cart's path.
        width: Image width [px].
        height: Image height [px].
        hfov_deg: Horizontal field of view [deg].
        fps: Camera frame rate [Hz].
        frames: Number of camera frames.
        compressed: Write JPEG ``CompressedImage`` rather than raw ``Image``.
        jpeg_quality: JPEG quality (1-100).
        odom_rate: Odometry and ``/tf`` rate [Hz].
        odom_noise: Odometry drift [m per sqrt(m) travelled]; yaw drifts by the same number in rad.
        exposure: Exposure time for motion blur [s]; 0 for none.
        sensor_noise: Standard deviation of sensor noise [8-bit levels].
        shadows: Cast shadows.
        lighting: Sun and sky.
        threads: Ray-casting threads (0: all cores).

    """

    seed: int = 0
    scene: SceneConfig = field(default_factory=SceneConfig)
    path: PathConfig = field(default_factory=PathConfig)
    width: int = 1280
    height: int = 960
    hfov_deg: float = 70.0
    fps: float = 15.0
    frames: int = 150
    compressed: bool = True
    jpeg_quality: int = 90
    odom_rate: float = 30.0
    odom_noise: float = 0.0
    exposure: float = 0.0
    sensor_noise: float = 1.5
    shadows: bool = True
    lighting: Lighting = field(default_factory=Lighting)
    threads: int = 0

    def camera(self) -> CameraModel:
        """Return the camera model (pinhole, no distortion)."""
        return CameraModel.from_fov(self.width, self.height, self.hfov_deg)


@dataclass
class SimulationSummary:
    """What :func:`simulate` wrote.

    Attributes:
        bag: The bag folder.
        truth: The truth folder.
        frames: Camera frames written.
        rocks: Number of rocks.
        truth_data: The content of ``truth.json``.

    """

    bag: Path
    truth: Path
    frames: int
    rocks: int
    truth_data: dict[str, Any]


def truth_folder(bag: str | Path) -> Path:
    """Return the truth folder that belongs to ``bag``: ``<BAG>_truth`` beside it."""
    p = Path(bag)
    return p.parent / f'{p.name}_truth'


def motion_blur(
    linear: npt.NDArray[np.float32], shift_px: npt.NDArray[np.float64]
) -> npt.NDArray[np.float32]:
    """Blur along the image motion ``shift_px`` (dx, dy) during the exposure (box kernel)."""
    length = float(np.hypot(*shift_px))
    if length < 1.0:
        return linear
    size = int(np.ceil(length)) | 1
    kernel = np.zeros((size, size), dtype=np.float32)
    c = size // 2
    d = shift_px / length
    for s in np.linspace(-length / 2, length / 2, 2 * size):
        x, y = round(c + s * d[0]), round(c + s * d[1])
        kernel[y, x] += 1.0
    kernel /= kernel.sum()
    return np.asarray(cv2.filter2D(linear, -1, kernel, borderType=cv2.BORDER_REFLECT))


def finish_image(
    linear: npt.NDArray[np.float32], rng: np.random.Generator, noise: float
) -> npt.NDArray[np.uint8]:
    """SRGB encoding with sensor noise (shot noise grows with the signal) of a linear image."""
    srgb = linear_to_srgb(linear)
    if noise > 0:
        sigma = noise * np.sqrt(0.3 + srgb / 255.0)
        srgb += rng.standard_normal(srgb.shape, dtype=np.float32) * sigma
    return np.asarray(np.clip(np.round(srgb), 0, 255), dtype=np.uint8)


def odometry_track(
    path: CartPath, times: npt.NDArray[np.float64], sigma: float, rng: np.random.Generator
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Odometry of the cart at ``times``: positions (Nx3) and yaws (N), drifting by ``sigma``.

    Each step's motion, in the cart's frame, is perturbed by noise growing with the square root of
    the distance travelled, then integrated from the true start pose, as wheel odometry drifts.
    """
    true = [path.base_pose(float(t)) for t in times]
    pos = np.array([p for p, _ in true])
    yaw = np.unwrap(np.array([y for _, y in true]))
    if sigma <= 0 or len(times) < 2:
        return pos, yaw
    out_pos = np.empty_like(pos)
    out_yaw = np.empty_like(yaw)
    out_pos[0], out_yaw[0] = pos[0], yaw[0]
    for k in range(1, len(times)):
        c, s = np.cos(yaw[k - 1]), np.sin(yaw[k - 1])
        step = pos[k] - pos[k - 1]
        local = np.array([c * step[0] + s * step[1], -s * step[0] + c * step[1]])
        scale = sigma * np.sqrt(np.linalg.norm(step))
        local += rng.normal(0.0, scale, size=2)
        dyaw = yaw[k] - yaw[k - 1] + rng.normal(0.0, scale)
        c2, s2 = np.cos(out_yaw[k - 1]), np.sin(out_yaw[k - 1])
        out_pos[k] = out_pos[k - 1] + np.array(
            [c2 * local[0] - s2 * local[1], s2 * local[0] + c2 * local[1], 0.0]
        )
        out_yaw[k] = out_yaw[k - 1] + dyaw
    return out_pos, out_yaw


def _yaw_quat(yaw: float) -> npt.NDArray[np.float64]:
    return np.array([0.0, 0.0, np.sin(yaw / 2), np.cos(yaw / 2)])


def _scene_dict(cfg: SimulationConfig, scene: Scene) -> dict[str, Any]:
    """Every generation parameter, JSON-ready."""
    pile = cfg.scene.pile
    return {
        'rocks': pile.rocks,
        'gradation': pile.gradation.as_dict(),
        'flat_fraction': pile.flat_fraction,
        'elongated_fraction': pile.elongated_fraction,
        'spread': pile.spread,
        'roughness': pile.roughness,
        'rounding': pile.rounding,
        'subdivisions': pile.subdivisions,
        'settling_cell': pile.cell,
        'dimension_method': DIMENSION_METHOD,
        'path': {**asdict(cfg.path), 'heights': list(cfg.path.heights)},
        'fps': cfg.fps,
        'frames': cfg.frames,
        'hfov_deg': cfg.hfov_deg,
        'compressed': cfg.compressed,
        'jpeg_quality': cfg.jpeg_quality,
        'odom_rate': cfg.odom_rate,
        'odom_noise': cfg.odom_noise,
        'exposure': cfg.exposure,
        'sensor_noise': cfg.sensor_noise,
        'shadows': cfg.shadows,
        'lighting': asdict(cfg.lighting),
        'start_ns': START_NS,
        'ground_half': GROUND_HALF,
        'ground_px': cfg.scene.ground_px,
        'target': cfg.scene.target,
        'rock_shapes': {str(r.id): r.shape for r in scene.rocks},
    }


def _target_dict(scene: Scene) -> dict[str, Any] | None:
    b = scene.board
    if b is None:
        return None
    return {
        'kind': 'charuco',
        'squares_x': b.squares_x,
        'squares_y': b.squares_y,
        'square_length': b.square_length,
        'marker_length': b.marker_length,
        'dictionary': b.dictionary,
        'corners_world': [[float(v) for v in p] for p in b.charuco_corners_world()],
        'corners_order': 'ChArUco inner chessboard corner ids (OpenCV CharucoBoard)',
        'board_corners_world': [
            [float(v) for v in p]
            for p in b.to_world(
                np.array(
                    [[0.0, 0.0], [0.0, b.size()[1]], [b.size()[0], b.size()[1]], [b.size()[0], 0.0]]
                )
            )
        ],
    }


def simulate(cfg: SimulationConfig, bag: str | Path) -> SimulationSummary:
    """Render the recording of ``cfg`` into the MCAP bag ``bag`` and its truth folder.

    Raises:
        StockpileError: The bag or truth folder exists already, or the configuration is invalid.

    """
    bag_path = Path(bag)
    truth_path = truth_folder(bag_path)
    if bag_path.exists():
        raise StockpileError(f'{bag_path} exists already; choose another --out or remove it')
    if truth_path.exists():
        raise StockpileError(f'{truth_path} exists already; remove it first')
    if cfg.frames < 2 or cfg.fps <= 0 or cfg.odom_rate <= 0:
        raise StockpileError('need at least 2 frames and positive frame and odometry rates')
    if not 1 <= cfg.jpeg_quality <= 100:
        raise StockpileError(f'JPEG quality {cfg.jpeg_quality} is not in 1..100')
    scene = build_scene(cfg.seed, cfg.scene)
    camera = cfg.camera()
    renderer = Renderer(
        scene.rocks,
        camera,
        scene.rock_textures,
        scene.ground,
        scene.board,
        cfg.lighting,
        shadows=cfg.shadows,
        threads=cfg.threads,
        ground_half=GROUND_HALF,
    )
    duration = (cfg.frames - 1) / cfg.fps
    if cfg.path.distance is None:
        reach = max(
            float(np.linalg.norm(r.mesh.vertices[:, :2], axis=1).max()) for r in scene.rocks
        )
        cfg = replace(cfg, path=replace(cfg.path, distance=auto_distance(reach)))
    path = CartPath(cfg.path, duration)
    noise_seq, odom_seq = np.random.SeedSequence([cfg.seed, 1]).spawn(2)
    noise_rng = np.random.default_rng(noise_seq)
    frame_times = np.arange(cfg.frames) / cfg.fps
    odom_times = np.arange(0.0, duration + 1e-9, 1.0 / cfg.odom_rate)
    odom_pos, odom_yaw = odometry_track(
        path, odom_times, cfg.odom_noise, np.random.default_rng(odom_seq)
    )
    steps = np.linalg.norm(np.diff(odom_pos, axis=0), axis=1)
    travelled = np.concatenate([[0.0], np.cumsum(steps)])
    visibility = VisibilityAccumulator(scene.rocks)
    cameras: list[dict[str, Any]] = []
    two_heights = len(cfg.path.heights) == 2

    bag_path.parent.mkdir(parents=True, exist_ok=True)
    # A half-written bag is useless and would block the next run: remove it on any failure.
    try:
        with BagWriter(bag_path) as writer:
            f = writer.factory
            link_t, link_r = path.mount(0.0)
            static = [
                m.transform_stamped(
                    f, START_NS, 'camera_link', 'camera_optical_frame', np.zeros(3),
                    quat_from_matrix(OPTICAL_IN_LINK),
                )
            ]  # fmt: skip
            if not two_heights:
                static.append(
                    m.transform_stamped(
                        f, START_NS, 'base_link', 'camera_link', link_t, quat_from_matrix(link_r)
                    )
                )
            writer.write('/tf_static', m.tf_message(f, static), START_NS)

            events = sorted(
                [(float(t), 0, k) for k, t in enumerate(odom_times)]
                + [(float(t), 1, k) for k, t in enumerate(frame_times)]
            )
            for t, kind, k in progress(events, 'rendering', unit='msg'):
                stamp = START_NS + round(t * 1e9)
                if kind == 0:
                    q = _yaw_quat(float(odom_yaw[k]))
                    sigma = cfg.odom_noise * np.sqrt(travelled[k])
                    writer.write(
                        ODOM_TOPIC,
                        m.odometry(f, stamp, odom_pos[k], q, position_sigma=float(sigma)),
                        stamp,
                    )
                    tfs = [m.transform_stamped(f, stamp, 'odom', 'base_link', odom_pos[k], q)]
                    if two_heights:
                        mt, mr = path.mount(t)
                        tfs.append(
                            m.transform_stamped(
                                f, stamp, 'base_link', 'camera_link', mt, quat_from_matrix(mr)
                            )
                        )
                    writer.write('/tf', m.tf_message(f, tfs), stamp)
                    continue
                position, rotation = path.camera_pose(t)
                result = renderer.render(position, rotation)
                visibility.add(result.rock_triangles)
                linear = result.linear
                if cfg.exposure > 0:
                    linear = motion_blur(
                        linear, _image_motion(path, camera, t, cfg.exposure, result.depth)
                    )
                img = finish_image(linear, noise_rng, cfg.sensor_noise)
                if cfg.compressed:
                    msg = m.compressed_image(
                        f, img, stamp, camera.frame_id, fmt='jpeg', quality=cfg.jpeg_quality
                    )
                    writer.write(IMAGE_TOPIC + '/compressed', msg, stamp)
                else:
                    writer.write(IMAGE_TOPIC, m.image(f, img, stamp, camera.frame_id), stamp)
                writer.write(INFO_TOPIC, m.camera_info(f, camera, stamp), stamp)
                cameras.append(
                    {
                        'stamp_ns': stamp,
                        'position': [float(v) for v in position],
                        'orientation_xyzw': [float(v) for v in quat_from_matrix(rotation)],
                    }
                )
    except BaseException:
        shutil.rmtree(bag_path, ignore_errors=True)
        raise

    fractions = visibility.fractions()
    rocks = [rock_truth(r, fractions.get(r.id, 0.0)) for r in scene.rocks]
    truth = {
        'schema': TRUTH_SCHEMA,
        'units': 'm',
        'frame_id': 'odom',
        'seed': cfg.seed,
        'scene': _scene_dict(cfg, scene),
        'camera': {
            'width': camera.width,
            'height': camera.height,
            'k': [float(v) for v in camera.k.reshape(-1)],
            'd': [],
            'distortion_model': camera.distortion_model,
        },
        'cameras': cameras,
        'target': _target_dict(scene),
        'specific_gravity': SPECIFIC_GRAVITY,
        'rocks': rocks,
        'gradation': to_json(gradation([r['b'] for r in rocks], [r['mass'] for r in rocks])),
    }
    write_truth(truth_path, truth, scene_mesh(scene.rocks, GROUND_HALF))
    return SimulationSummary(bag_path, truth_path, cfg.frames, len(scene.rocks), truth)


def _image_motion(
    path: CartPath, camera: CameraModel, t: float, exposure: float, depth: npt.NDArray[np.float32]
) -> npt.NDArray[np.float64]:
    """Pixel motion of the scene point at the image centre during the exposure around ``t``."""
    d = float(depth[camera.height // 2, camera.width // 2])
    if not np.isfinite(d):
        d = 5.0
    p0, r0 = path.camera_pose(t)
    ray = np.array([0.0, 0.0, 1.0]) * d
    point = p0 + r0 @ ray
    pixels = []
    for dt in (-exposure / 2, exposure / 2):
        p, r = path.camera_pose(t + dt)
        x = r.T @ (point - p)
        pixels.append(camera.k[:2, :2] @ (x[:2] / x[2]))
    return np.asarray(pixels[1] - pixels[0])
