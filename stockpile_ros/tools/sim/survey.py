"""A simulated survey cloud of a pile or a bed (terrestrial or phone LiDAR), with its truth folder.

The pile is the simulator's (:func:`~.pile.build_pile`), or a bed of rocks covering the ground
as a gravel bar's do (:func:`~.bed.build_bed`); the cloud samples its visible union
surface (:func:`~stockpile_ros.tools.synthetic.sample_scene`) as seen from a ring of scanner
positions and one overhead, uniformly in area at a chosen spacing, with Gaussian range noise,
then moves it into a survey frame (tilted, far from the origin as georeferenced coordinates are)
so that the levelling and the float precision are tested too. Points are spread as a scanner's
are, one to a cell of a grid. The truth (``truth.json``,
``scene.ply``) stays in the pile's frame, ``pile``; ``survey_to_pile`` maps the cloud back.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.spatial.transform import Rotation

from ...artefacts import MeshInfo, load, to_json
from ...bagio.writer import BagWriter
from ...geometry import Similarity
from ...meshio import LabelledMesh
from ...result import Report
from ...ros import messages as m
from ...ros.outputs import pointcloud2
from ...segment.gradation import gradation
from ..evaluation import EvaluationError, evaluate_sides, load_result, load_truth
from ..synthetic import SyntheticPile, sample_scene, seen_from
from .bed import BedConfig, build_bed
from .pile import PileConfig, build_pile
from .truth import SPECIFIC_GRAVITY, TRUTH_SCHEMA, rock_truth, scene_mesh, write_truth

__all__ = ['Survey', 'score_survey', 'simulate_survey', 'write_scan_bag']

F64 = npt.NDArray[np.float64]

# Samples per spacing squared drawn before one per grid cell is kept: enough that nearly every
# cell the surface crosses holds one.
_OVERSAMPLE = 8.0
# A surface crosses about two grid cells per cell area: cells of 1.5 spacings give a median
# nearest-neighbour distance near the spacing (0.64 cell measured).
_CELL = 1.5


@dataclass(frozen=True)
class Survey:
    """A simulated survey.

    Attributes:
        points: Nx3 points in the survey frame.
        normals: Nx3 true unit normals (survey frame).
        labels: N true labels (0 ground, else the rock id).
        survey_to_pile: Maps survey coordinates into the truth frame.
        truth: The ``truth.json`` dict.

    """

    points: F64
    normals: F64
    labels: npt.NDArray[np.int32]
    survey_to_pile: Similarity
    truth: dict[str, Any]


def simulate_survey(
    out: str | Path,
    pile: PileConfig | BedConfig,
    *,
    seed: int = 0,
    spacing: float = 0.01,
    noise: float = 0.002,
    noise_growth: float = 0.0,
    falloff: float = 0.0,
    aspect: float = 1.0,
    overhead: bool = True,
    footprint: float = 0.0,
    registration: float = 0.0,
    tilt_deg: float = 10.0,
    offset: tuple[float, float, float] = (500_000.0, 5_000_000.0, 300.0),
) -> Survey:
    """Build a pile, write its truth folder into ``out`` and return a survey cloud of it.

    Args:
        out: Truth folder (created).
        pile: The pile, or the bed.
        seed: Random seed of the pile, the samples and the noise.
        spacing: Median distance between neighbouring points, about [m].
        noise: Standard deviation of the range noise, along each point's normal [m].
        noise_growth: The noise grows with range as ``(d / d_min) ** noise_growth``, ``d`` a
            point's distance to the nearest scanner position: ``noise`` is the nearest point's,
            and 1 or 2 make the far side of the pile several times noisier, as a phone's depth
            or a scanner beyond its best range is (0: the same everywhere).
        falloff: Each point is kept with probability ``(d_min / d) ** falloff``, ``d`` its
            distance to the nearest scanner position: 2 thins the points with range as a
            scanner's angular step does (its density falls as the range squared), so that
            ``spacing`` is the spacing nearest a scanner; 0 keeps one point to a cell everywhere.
        aspect: The cells one point is kept from are this many times longer along the pile's y
            than along x and z: rows swept densely along x, far apart across them, as a
            scanner's rows at a glancing angle or a cart's LiDAR's rings are (1: even).
        overhead: Whether a scanner position above the middle sees the pile too (as a drone or
            a mast would); without it only the ring of tripods 1.5 m high sees it, at a glancing
            angle, and every rock shadows the ground and the rocks behind it.
        footprint: Width of a scanner's beam where it meets the surface [spacings; 0: a beam
            sees one point]. Each point is scanned from one of the positions that see it; where
            its beam straddles the silhouette of one surface against another (a rock against
            the ground or a rock behind it), it returns a range drawn uniformly between the two,
            along the beam's middle: a mixed pixel, in the air between the two surfaces.
        registration: Error of registering each position's scan to the others [m]: every
            position's points are shifted together by a draw of this standard deviation along
            each axis, so that where two scans overlap the surface is drawn twice, apart.
        tilt_deg: Tilt of the survey frame's z from the pile's up [degrees].
        offset: Where the pile's origin lies in the survey frame [m].

    """
    rng = np.random.default_rng(seed)
    rocks = build_bed(rng, pile) if isinstance(pile, BedConfig) else build_pile(rng, pile)
    reach = max(float(np.abs(r.mesh.vertices[:, :2]).max()) for r in rocks)
    ground_half = reach + 0.5
    scene = scene_mesh(rocks, ground_half)
    ring = np.radians(np.arange(0.0, 360.0, 45.0))
    eyes = np.column_stack([2.5 * reach * np.cos(ring), 2.5 * reach * np.sin(ring),
                            np.full(len(ring), 1.5)])  # fmt: skip
    if overhead:
        eyes = np.vstack([eyes, [[0.0, 0.0, 3.0 * reach]]])
    density = _OVERSAMPLE / spacing**2
    dense = sample_scene(scene.vertices, scene.faces, scene.labels, density, margin=0.3,
                         seed=seed, viewpoints=eyes)  # fmt: skip
    counts = np.bincount(dense.labels, minlength=max(r.id for r in rocks) + 1)
    truths = []
    for rock in rocks:
        record = rock_truth(rock, 0.0)
        record['visible_fraction'] = min(1.0, float(counts[rock.id]) / (record['area'] * density))
        truths.append(record)
    # One sample per cell of a grid, as evenly as a scanner's sweep lays them (not in the clumps
    # of uniform random samples).
    cells = np.floor(dense.points / (_CELL * spacing * np.array([1.0, aspect, 1.0]))).astype(
        np.int64
    )
    _, first = np.unique(cells, axis=0, return_index=True)
    if falloff > 0:
        # Thinned at random, not on a coarser grid: gaps and clumps, as where stations overlap.
        eye = _nearest(dense.points[first], eyes)
        first = first[rng.random(len(first)) < (eye.min() / eye) ** falloff]
    sampled = SyntheticPile([], dense.points[first], dense.normals[first], dense.labels[first])
    mixed = 0
    if footprint > 0 or registration > 0:
        # Its own stream: the points and noise of a survey without either stay the same.
        moved, mixed = _scanned(
            sampled, eyes, scene, footprint * spacing, registration,
            np.random.default_rng([seed, 1]),
        )  # fmt: skip
        sampled = SyntheticPile([], moved, sampled.normals, sampled.labels)
    truth = {
        'schema': TRUTH_SCHEMA,
        'units': 'm',
        'frame_id': 'pile',
        'seed': seed,
        'scene': {'survey': {'spacing': spacing, 'noise': noise, 'noise_growth': noise_growth,
                             'falloff': falloff,
                             'aspect': aspect, 'overhead': overhead, 'footprint': footprint,
                             'mixed_pixels': mixed, 'registration': registration,
                             'tilt_deg': tilt_deg,
                             'rocks': pile.rocks, 'gradation': pile.gradation.as_dict(),
                             'bed': isinstance(pile, BedConfig), 'rounding': pile.rounding}},
        'cameras': [],
        'target': None,
        'specific_gravity': SPECIFIC_GRAVITY,
        'rocks': truths,
        'gradation': to_json(gradation([r['b'] for r in truths], [r['mass'] for r in truths])),
    }  # fmt: skip
    write_truth(out, truth, scene)
    spread = rng.normal(0.0, noise, len(sampled.points))
    if noise_growth:
        ranges = _nearest(sampled.points, eyes)
        spread *= (ranges / ranges.min()) ** noise_growth
    points = sampled.points + spread[:, None] * sampled.normals
    axis = rng.normal(size=3)
    axis[2] = 0.0
    axis /= np.linalg.norm(axis)
    rotation = Rotation.from_rotvec(np.radians(tilt_deg) * axis).as_matrix()
    shift = np.asarray(offset, dtype=np.float64)
    to_pile = Similarity(1.0, rotation.T, -rotation.T @ shift)
    return Survey(
        points=points @ rotation.T + shift,
        normals=sampled.normals @ rotation.T,
        labels=sampled.labels,
        survey_to_pile=to_pile,
        truth=truth,
    )


def _nearest(points: F64, eyes: F64) -> F64:
    """Return each point's distance to the nearest scanner position [m]."""
    return np.asarray(np.min(np.linalg.norm(points[:, None] - eyes[None], axis=2), axis=1))


def _scanned(
    sampled: SyntheticPile,
    eyes: F64,
    scene: LabelledMesh,
    width: float,
    registration: float,
    rng: np.random.Generator,
) -> tuple[F64, int]:
    """Return the points as the scanner positions would give them, and how many were mixed.

    Each point is scanned from one of the positions that see it; with ``width`` > 0 a beam
    that wide straddling two surfaces returns a range between them (a mixed pixel), and with
    ``registration`` > 0 every position's points are shifted together by the error of
    registering its scan to the others (that standard deviation along each axis).
    """
    import open3d

    o3d: Any = open3d

    tensor = o3d.core.Tensor
    caster = o3d.t.geometry.RaycastingScene()
    caster.add_triangles(
        tensor(scene.vertices.astype(np.float32)), tensor(scene.faces.astype(np.uint32))
    )

    def cast(origins: F64, directions: F64) -> tuple[F64, npt.NDArray[np.int64]]:
        rays = np.hstack([origins, directions]).astype(np.float32)
        hit = caster.cast_rays(tensor(rays))
        return hit['t_hit'].numpy().astype(np.float64), hit['primitive_ids'].numpy().astype(
            np.int64
        )

    points = sampled.points
    rocks = scene.labels > 0
    seen = seen_from(scene.vertices, scene.faces[rocks], points, sampled.normals, eyes)
    station = np.argmax(rng.random(seen.shape) * seen, axis=1)
    eye = eyes[station]
    out = points.copy()
    mixed = np.zeros(len(points), dtype=bool)
    if width > 0:
        beam = points - eye
        reach = np.linalg.norm(beam, axis=1)
        beam /= reach[:, None]
        side = rng.normal(size=points.shape)
        side -= np.einsum('ij,ij->i', side, beam)[:, None] * beam
        side /= np.linalg.norm(side, axis=1, keepdims=True)
        edge = points + width * side - eye
        edge /= np.linalg.norm(edge, axis=1, keepdims=True)
        t_edge, face = cast(eye, edge)
        hit = np.isfinite(t_edge)
        other = np.full(len(points), -1, dtype=np.int64)
        other[hit] = scene.labels[face[hit]]
        mixed = seen.any(axis=1) & hit & (other != sampled.labels)
        share = rng.random(len(points))
        out[mixed] = (
            eye[mixed]
            + beam[mixed] * (reach[mixed] + share[mixed] * (t_edge[mixed] - reach[mixed]))[:, None]
        )
    if registration > 0:
        out += rng.normal(0.0, registration, (len(eyes), 3))[station]
    return out, int(mixed.sum())


def score_survey(
    result_dir: str | Path,
    truth_dir: str | Path,
    survey: Survey,
    mesh_info: MeshInfo | None = None,
) -> dict[str, Any]:
    """Score a result made from a survey cloud against its truth (:func:`~.evaluation.evaluate`).

    A cloud has no keyframes to align by: the result is moved back into the cloud's frame with the
    transform the run itself recorded (``model_to_stockpile`` of ``mesh_info``, the run's
    ``mesh.json``, or of ``report.json``'s ``mesh``), then into the truth frame with
    ``survey.survey_to_pile``.
    """
    result = load_result(result_dir)
    report = load(Report, Path(result_dir) / 'report.json')
    record = report.mesh.model_to_stockpile if mesh_info is None else mesh_info.model_to_stockpile
    if record is None:
        raise EvaluationError(f'{result_dir}: the report records no model_to_stockpile')
    rotation = np.asarray(record.rotation, dtype=np.float64).reshape(3, 3)
    scale, shift = record.scale, np.asarray(record.translation, dtype=np.float64)
    metres = report.scale.metres_per_unit
    to = survey.survey_to_pile

    def back(points: F64) -> F64:
        # x_stockpile = scale R x_cloud + t, with x_cloud in the cloud's units.
        return to.apply(((points - shift) @ rotation) / scale * metres)

    result.mesh.vertices = back(result.mesh.vertices)
    for rock in result.rocks.values():
        if rock.centroid is not None:
            rock.centroid = back(rock.centroid.reshape(1, 3))[0]
    result.frame_id = str(survey.truth['frame_id'])
    return evaluate_sides(result, load_truth(truth_dir))


def write_scan_bag(
    bag: str | Path, survey: Survey, *, scans: int = 16, height: float = 1.5, seed: int = 0
) -> Path:
    """Write a cart circling the pile with a LiDAR on a mast scanning ``survey``, as a ROS 2 bag.

    The survey must be in the pile's frame (``tilt_deg=0``, ``offset`` zero): that frame is the
    odometry frame ``odom``. Each point goes to one scan among those whose sensor it faces (every
    point once: a real sensor samples new places each sweep), in the sensor frame ``lidar_link``.
    Topics: ``/points`` (PointCloud2, x, y, z), ``/odom`` and ``/tf`` (``odom`` -> ``base_link``,
    ten poses a scan) and ``/tf_static`` (``base_link`` -> ``lidar_link``: up the mast, turned
    and pitched towards the pile).
    """
    rng = np.random.default_rng(seed)
    points = survey.points
    radius = 1.3 * float(np.max(np.linalg.norm(points[:, :2], axis=1)))
    mount = Rotation.from_euler('zy', [0.0, 30.0], degrees=True)
    steps = 10
    angles = np.linspace(0.0, 2 * np.pi, scans * steps, endpoint=False)
    bases = np.column_stack(
        [radius * np.cos(angles), radius * np.sin(angles), np.zeros(len(angles))]
    )
    yaws = Rotation.from_euler('z', (angles + np.pi)[:, None])
    sensors = bases[::steps] + np.array([0.0, 0.0, height])
    facing = np.einsum('sij,ij->is', sensors[:, None, :] - points[None], survey.normals) > 0
    weights = facing / np.maximum(facing.sum(axis=1, keepdims=True), 1)
    cumulative = np.cumsum(weights, axis=1)
    owner = (cumulative < rng.random(len(points))[:, None]).sum(axis=1)
    owner[~facing.any(axis=1)] = -1
    start = 1_000_000_000
    with BagWriter(Path(bag)) as writer:
        f = writer.factory
        static = m.transform_stamped(f, start, 'base_link', 'lidar_link', [0.0, 0.0, height],
                                     mount.as_quat())  # fmt: skip
        writer.write('/tf_static', m.tf_message(f, [static]), start)
        for k, (base, yaw) in enumerate(zip(bases, yaws, strict=True)):
            t = start + k * 10_000_000
            quat = yaw.as_quat()
            writer.write('/odom', m.odometry(f, t, base, quat), t)
            tf = m.transform_stamped(f, t, 'odom', 'base_link', base, quat)
            writer.write('/tf', m.tf_message(f, [tf]), t)
            if k % steps == 0:
                to_lidar = (yaw * mount).inv()
                seen = points[owner == k // steps] - sensors[k // steps]
                cloud = pointcloud2(f, to_lidar.apply(seen), None, None, t, 'lidar_link')
                writer.write('/points', cloud, t)
    return Path(bag)
