"""From collector, run outcomes and results to the (topic, message) pairs the node set publishes.

Written once over a :class:`~stockpile_ros.ros.messages.MessageFactory`: the replay serialises the
messages with rosbags, the nodes publish them with rclpy. Topic names are the relative names of
:mod:`stockpile_ros.ros.topics` (the replay makes them absolute).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.spatial.transform import Rotation

from ..artefacts import DenseSummary, MeshInfo, SparseSummary, WorkFolder, load
from ..recon.collector import CollectorState
from ..recon.scaling import odom_from_stockpile
from ..result import Report
from ..runner import Outcome
from ..segment.pipeline import Analysis
from . import topics
from .messages import MessageFactory, tf_message, transform_stamped
from .outputs import (
    diagnostic_array,
    gradation_msg,
    marker_array,
    mesh_marker_array,
    pipeline_status,
    pointcloud2,
    rock_array,
    rock_color,
)

__all__ = [
    'DIAGNOSTIC_PREFIX',
    'Publication',
    'capture_warnings',
    'diagnostics',
    'keyframe_status',
    'reconstruction_diagnostics',
    'reconstruction_outputs',
    'segmentation_outputs',
    'status',
]

Publication = tuple[str, Any]
"""A relative topic name and the message to publish on it."""

DIAGNOSTIC_PREFIX = 'stockpile'
"""Diagnostic status names are ``stockpile/<stage>``."""

# Relative scale uncertainty above which the scale is flagged.
_SCALE_WARN = 0.05


def status(
    f: MessageFactory,
    stamp_ns: int,
    state: str,
    stage: str,
    collector: CollectorState | None,
    message: str,
    advice: str = '',
    progress: float = 0.0,
    topic: str = topics.STATUS,
) -> Publication:
    """Build a ``PipelineStatus`` on ``topic`` (the pipeline status by default)."""
    return topic, pipeline_status(
        f, stamp_ns, state, stage, progress,
        collector.keyframes if collector else 0, collector.coverage if collector else 0.0,
        message, advice,
    )  # fmt: skip


def keyframe_status(f: MessageFactory, stamp_ns: int, collector: CollectorState) -> Publication:
    """Build the keyframe node's status: keyframes held, coverage and the last decision."""
    last = collector.last
    reasons = ', '.join(f'{k} {v}' for k, v in sorted(collector.decisions.items()))
    message = (
        f'{collector.keyframes} keyframes from {collector.frames} frames; coverage '
        f'{collector.coverage:.2f} ({collector.coverage_source}); last: '
        f'{last.reason if last else "none"}; decisions: {reasons or "none"}'
    )
    return status(
        f, stamp_ns, 'COLLECTING', 'keyframes', collector, message, topic=topics.KEYFRAME_STATUS
    )


def diagnostics(
    f: MessageFactory,
    stamp_ns: int,
    name: str,
    level: str,
    message: str,
    values: dict[str, Any] | None = None,
) -> Publication:
    """Build a one-status ``DiagnosticArray`` named ``stockpile/<name>``."""
    entry = {
        'name': f'{DIAGNOSTIC_PREFIX}/{name}',
        'level': level,
        'message': message,
        'hardware_id': 'stockpile',
        'values': values or {},
    }
    return topics.DIAGNOSTICS, diagnostic_array(f, stamp_ns, [entry])


def capture_warnings(f: MessageFactory, stamp_ns: int, report: Report) -> list[Publication]:
    """One ``stockpile/capture`` WARN diagnostic per warning of a report."""
    return [diagnostics(f, stamp_ns, 'capture', 'WARN', t) for t in report.warnings]


def _stage_values(
    result: SparseSummary | DenseSummary | MeshInfo,
) -> tuple[str, str, dict[str, Any]]:
    """Level, message and key values of a finished stage."""
    if isinstance(result, SparseSummary):
        sparse = {'keyframes': result.total, 'registered': result.registered,
                  'registered_fraction': result.registered_fraction, 'points': result.points,
                  'mean_reprojection_error_px': result.mean_reprojection_error_px}  # fmt: skip
        return 'OK', f'{result.registered} keyframes registered', sparse
    if isinstance(result, DenseSummary):
        return 'OK', f'{result.points} dense points', {'points': result.points}
    method, rel = result.scale.method, result.scale.rel_uncertainty
    values: dict[str, Any] = {
        'scale_method': method,
        'metres_per_unit': result.scale.metres_per_unit,
        'scale_rel_uncertainty': rel,
        'faces': result.poisson.get('faces'),
    }
    if method == 'none':
        return 'WARN', 'mesh ready, but without metric scale (no target, no odometry)', values
    if rel is not None and rel > _SCALE_WARN:
        return 'WARN', f'mesh ready; scale ({method}) uncertain by {100 * rel:.0f} %', values
    return 'OK', f'mesh ready; scale from {method}', values


def reconstruction_diagnostics(
    f: MessageFactory, stamp_ns: int, outcome: Outcome
) -> list[Publication]:
    """One ``DiagnosticArray`` per finished stage, and one ERROR for the failed stage if any."""
    out = []
    for stage, result in outcome.finished():
        level, message, values = _stage_values(result)
        values['seconds'] = round(outcome.seconds.get(stage, math.nan), 2)
        out.append(diagnostics(f, stamp_ns, stage, level, message, values))
    if not outcome.ok:
        advice = {'advice': outcome.advice}
        out.append(diagnostics(f, stamp_ns, outcome.stage, 'ERROR', outcome.reason, advice))
    return out


def _decimate(
    vertices: npt.NDArray[np.float64],
    faces: npt.NDArray[np.int64],
    colors: npt.NDArray[np.uint8] | None,
    max_faces: int,
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.int64], npt.NDArray[np.uint8] | None]:
    if len(faces) <= max_faces:
        return vertices, faces, colors
    import open3d as o3d

    mesh = o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector(vertices), o3d.utility.Vector3iVector(faces.astype(np.int32))
    )
    if colors is not None:
        mesh.vertex_colors = o3d.utility.Vector3dVector(colors / 255.0)
    small = mesh.simplify_quadric_decimation(max_faces)
    out_colors = None
    if colors is not None:
        out_colors = np.clip(np.round(np.asarray(small.vertex_colors) * 255), 0, 255)
        out_colors = out_colors.astype(np.uint8)
    return (
        np.asarray(small.vertices, dtype=np.float64),
        np.asarray(small.triangles, dtype=np.int64),
        out_colors,
    )


def reconstruction_outputs(
    f: MessageFactory, stamp_ns: int, work_dir: str | Path, frame_id: str, max_faces: int
) -> list[Publication]:
    """Build the dense cloud and the mesh of a finished reconstruction, in the stockpile frame.

    The dense cloud (model frame on disk) is moved with ``mesh.json``'s ``model_to_stockpile`` and
    thinned to at most ``max_faces`` points; the mesh is decimated to ``max_faces`` faces. With
    odometry, a ``/tf_static`` transform places the stockpile frame in the odometry frame, so that
    the camera and the pile show together.
    """
    import open3d as o3d

    from ..meshio import read_labelled_mesh

    work = Path(work_dir)
    to_stockpile = load(MeshInfo, work / 'mesh' / 'mesh.json').model_to_stockpile.similarity()
    cloud = o3d.io.read_point_cloud(work / 'dense' / 'dense.ply')
    points = to_stockpile.apply(np.asarray(cloud.points))
    colors = None
    if cloud.has_colors():
        colors = np.clip(np.round(np.asarray(cloud.colors) * 255), 0, 255).astype(np.uint8)
    step = max(1, math.ceil(len(points) / max_faces))
    mesh = read_labelled_mesh(work / 'mesh' / 'mesh.ply')
    verts, faces, vcol = _decimate(mesh.vertices, mesh.faces, mesh.colors, max_faces)
    frames = []
    if placed := odom_from_stockpile(WorkFolder(work)):
        odom, sim = placed
        quat = Rotation.from_matrix(sim.rotation).as_quat()
        transform = transform_stamped(f, stamp_ns, odom, frame_id, sim.translation, quat)
        frames.append((topics.TF_STATIC, tf_message(f, [transform])))
    return [
        *frames,
        (topics.DENSE_CLOUD, pointcloud2(
            f, points[::step], None if colors is None else colors[::step], None,
            stamp_ns, frame_id)),
        (topics.MESH, mesh_marker_array(f, verts, faces, stamp_ns, frame_id, vcol)),
    ]  # fmt: skip


def segmentation_outputs(
    f: MessageFactory, stamp_ns: int, analysis: Analysis, frame_id: str, max_faces: int
) -> list[Publication]:
    """Build the segmented cloud, rock markers, rock array and gradation of one analysis.

    The segmented cloud holds one point per mesh face (its centroid) with the rock id as
    ``label`` and the rock's marker colour as ``rgb`` (ground and unassigned faces grey). Rocks are
    drawn as their own faces when the mesh has at most ``max_faces`` faces, else as boxes.
    """
    report = analysis.report
    labels = np.asarray(analysis.segmentation.labels, dtype=np.int64)
    centroids = analysis.vertices[analysis.faces].mean(axis=1)
    palette = np.array(
        [rock_color(int(i)) for i in range(int(labels.max(initial=0)) + 1)], dtype=np.float64
    )
    colors = np.round(palette[labels] * 255).astype(np.uint8)
    mesh_args: dict[str, Any] = {}
    if len(analysis.faces) <= max_faces:
        mesh_args = {
            'vertices': analysis.vertices,
            'faces': analysis.faces,
            'face_labels': labels,
        }
    rocks = report.rocks
    return [
        (topics.SEGMENTED_CLOUD,
         pointcloud2(f, centroids, colors, labels, stamp_ns, frame_id)),
        (topics.ROCK_MARKERS, marker_array(f, rocks, stamp_ns, frame_id, **mesh_args)),
        (topics.ROCKS, rock_array(f, rocks, report.scale, stamp_ns, frame_id)),
        (topics.GRADATION, gradation_msg(f, report.gradation, stamp_ns, frame_id, report.units)),
    ]  # fmt: skip
