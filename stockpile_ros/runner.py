"""Reconstruction and segmentation runs that end in a status, never in an exception.

Both the reconstruction node's worker and ``stockpile replay`` call these: a capture that cannot be
reconstructed becomes an :class:`Outcome` with a reason and advice for the operator.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from .artefacts import DenseSummary, MeshInfo, SparseSummary, WorkFolder, load, save
from .cloud.mesh import cloud_segment_params, mesh_cloud
from .cloud.read import Cloud
from .errors import CaptureError, StockpileError
from .meshcheck import read_mesh
from .meshio import write_labelled_mesh
from .recon.keyframes import KeyframeStore
from .recon.pipeline import reconstruct
from .segment.pipeline import Analysis, analyse_mesh
from .segment.provenance import Provenance
from .segment.qa import report_options
from .segment.report import write_result_folder
from .settings import Settings, class_spec, defaults, smallest_rock_asked

__all__ = [
    'MIN_KEYFRAMES',
    'RECON_STAGES',
    'Outcome',
    'run_cloud_reconstruction',
    'run_reconstruction',
    'run_segmentation',
]

RECON_STAGES = ('sfm', 'dense', 'mesh')

MIN_KEYFRAMES = 3
"""Fewest keyframes worth a Structure-from-Motion attempt (two views and one to check them)."""

# What a capture or a pycolmap/open3d step raises when the data cannot be processed.
_FAILURES = (StockpileError, RuntimeError, ValueError, OSError)


@dataclass
class Outcome:
    """How a run ended.

    Attributes:
        ok: Whether every stage succeeded.
        stage: The stage that failed, or the last one run.
        reason: What went wrong ('' when ok).
        advice: What the operator should do ('' when ok).
        sparse: What the sfm stage made, when it finished.
        dense: What the dense stage made, when it finished.
        mesh: What the mesh stage made, when it finished.
        seconds: Each finished stage's duration by name.
        analysis: The segmentation analysis, report included (segmentation runs only).

    """

    ok: bool
    stage: str
    reason: str = ''
    advice: str = ''
    sparse: SparseSummary | None = None
    dense: DenseSummary | None = None
    mesh: MeshInfo | None = None
    seconds: dict[str, float] = field(default_factory=dict)
    analysis: Analysis | None = None

    def finished(self) -> list[tuple[str, SparseSummary | DenseSummary | MeshInfo]]:
        """Return the reconstruction stages that finished, in order, with what each made."""
        made = (('sfm', self.sparse), ('dense', self.dense), ('mesh', self.mesh))
        return [(stage, result) for stage, result in made if result is not None]


def _failure(stage: str, exc: Exception, outcome: Outcome) -> Outcome:
    outcome.ok = False
    outcome.stage = stage
    if isinstance(exc, CaptureError):
        outcome.reason, outcome.advice = exc.reason, exc.advice
    elif isinstance(exc, StockpileError):
        outcome.reason = str(exc)
        outcome.advice = 'Check the capture and the parameters, then trigger again'
    else:
        outcome.reason = f'{type(exc).__name__}: {exc}'
        outcome.advice = 'Unexpected failure of the stage; report it with the work folder'
    return outcome


def run_reconstruction(
    settings: Settings,
    on_stage: Callable[[str, int, float | None], None] | None = None,
) -> Outcome:
    """Run the sfm, dense and mesh stages over the work folder's keyframes.

    Args:
        settings: Options and work folder.
        on_stage: Called with the stage name, its index in :data:`RECON_STAGES` and, once it is
            done, its duration [s] (None when it starts).

    Returns:
        The outcome, with what each stage that finished made.

    """
    outcome = Outcome(ok=True, stage=RECON_STAGES[0])
    held = len(KeyframeStore(WorkFolder(settings.work_dir).keyframes).records)
    if held < MIN_KEYFRAMES:
        too_few = CaptureError(
            'keyframes',
            f'only {held} keyframe{"" if held == 1 else "s"} held, at least {MIN_KEYFRAMES} needed',
            'Move the camera around the pile (sharp frames, steady motion) before triggering',
        )
        return _failure('keyframes', too_few, outcome)
    for index, stage in enumerate(RECON_STAGES):
        if on_stage is not None:
            on_stage(stage, index, None)
        start = time.perf_counter()
        try:
            result = reconstruct(None, settings.work_dir, settings.recon, stage)[stage]
        except _FAILURES as exc:
            return _failure(stage, exc, outcome)
        outcome.stage = stage
        if isinstance(result, SparseSummary):
            outcome.sparse = result
        elif isinstance(result, DenseSummary):
            outcome.dense = result
        elif isinstance(result, MeshInfo):
            outcome.mesh = result
        outcome.seconds[stage] = time.perf_counter() - start
        if on_stage is not None:
            on_stage(stage, index, outcome.seconds[stage])
    return outcome


def run_cloud_reconstruction(
    settings: Settings,
    cloud: Cloud,
    viewpoints: npt.NDArray[np.float64] | None,
    on_stage: Callable[[str, int, float | None], None] | None = None,
    stream: dict[str, Any] | None = None,
) -> Outcome:
    """Mesh an accumulated sensor cloud (metres, its frame the model frame) into the work folder.

    Writes ``dense/dense.ply`` (the cloud) and ``dense.json``, then ``mesh/mesh.ply`` and
    ``mesh.json`` (scale method ``sensor``: a range sensor measures metres) as the mesh stage of
    :func:`run_reconstruction` would, so that everything downstream reads the same files.

    Args:
        settings: Options and work folder.
        cloud: The accumulated cloud.
        viewpoints: Per point, a place towards the sensor that saw it (normals turn that way).
        on_stage: As for :func:`run_reconstruction`.
        stream: What the accumulation saw, kept in ``mesh.json`` as ``cloud.stream``.

    Returns:
        The outcome of the one stage, ``mesh``, with what it made.

    """
    import open3d

    o3d: Any = open3d
    outcome = Outcome(ok=True, stage='mesh')
    work = WorkFolder(settings.work_dir)
    if on_stage is not None:
        on_stage('mesh', RECON_STAGES.index('mesh'), None)
    start = time.perf_counter()
    try:
        mesh, info = mesh_cloud(cloud, settings.cloud, settings.recon.poisson, 1.0, 'sensor',
                                viewpoints, smallest_rock_asked(settings))  # fmt: skip
        if stream is not None and info.cloud is not None:
            info.cloud['stream'] = stream
        work.dense.mkdir(parents=True, exist_ok=True)
        pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(cloud.points))
        if cloud.colors is not None:
            pcd.colors = o3d.utility.Vector3dVector(cloud.colors / 255.0)
        o3d.io.write_point_cloud(work.dense / 'dense.ply', pcd)
        dense = DenseSummary(
            'sensor cloud', False, len(cloud.points), extra={'source': cloud.source}
        )
        save(dense, work.dense / 'dense.json')
        work.mesh.mkdir(parents=True, exist_ok=True)
        write_labelled_mesh(work.mesh / 'mesh.ply', mesh)
        save(info, work.mesh / 'mesh.json')
    except _FAILURES as exc:
        return _failure('mesh', exc, outcome)
    outcome.dense, outcome.mesh = dense, info
    outcome.seconds['mesh'] = time.perf_counter() - start
    if on_stage is not None:
        on_stage('mesh', RECON_STAGES.index('mesh'), outcome.seconds['mesh'])
    return outcome


def run_segmentation(
    settings: Settings,
    mesh_dir: Path,
    result_dir: str | Path | None = None,
    provenance: Provenance | None = None,
) -> Outcome:
    """Segment a mesh folder's surface, measure the rocks and write the result folder.

    Args:
        settings: Parameters, class to check and work folder.
        mesh_dir: Folder holding ``mesh.ply`` and ``mesh.json``; the keyframe photo of the page
            comes from the ``keyframes/`` folder beside it.
        result_dir: Result folder (``<work_dir>/result`` by default).
        provenance: What the run was made from; None: the mesh file itself is the input
            (the parameters, site, pile and operator from ``settings``).

    Returns:
        The outcome, ``analysis`` (with the report) set when ok.

    """
    outcome = Outcome(ok=True, stage='segment')
    out = Path(result_dir) if result_dir is not None else settings.work_dir / 'result'
    start = time.perf_counter()
    try:
        mesh, check = read_mesh(mesh_dir / 'mesh.ply')
        info = load(MeshInfo, mesh_dir / 'mesh.json')
        spec = class_spec(settings)
        options = report_options(settings.values)
        analysis = analyse_mesh(
            mesh.vertices, mesh.faces, mesh.colors,
            seg_params=cloud_segment_params(settings.segment, info, settings.explicit),
            measure_params=settings.measure,
            spec=spec, mesh_info=info, source=str(mesh_dir / 'mesh.ply'),
            report_options=options,
        )  # fmt: skip
        analysis.report.mesh.check = check
        if info.scale.metric:
            # In model units (no scale) a size in metres says nothing.
            analysis.report.warnings[:0] = check.warnings
        made = provenance or Provenance.for_input(
            mesh_dir / 'mesh.ply', settings.values, defaults()
        )
        write_result_folder(out, analysis, made, options, mesh_dir.parent / 'keyframes')
    except (json.JSONDecodeError, KeyError) as exc:
        return _failure('segment', StockpileError(f'{mesh_dir}: unreadable mesh: {exc}'), outcome)
    except _FAILURES as exc:
        return _failure('segment', exc, outcome)
    outcome.analysis = analysis
    outcome.seconds['segment'] = time.perf_counter() - start
    return outcome
