"""``stockpile replay`` of a folder of photos or a video file: no ROS stream, the same result.

A bag goes through the node set's components (:mod:`stockpile_ros.replay`). Photos and a phone's
video have no CameraInfo, odometry or transforms to feed them, so this driver selects keyframes
straight into the work folder (every sharp photo; the keyframe selector over a video's frames),
then runs the very reconstruction and segmentation the replay runs
(:func:`~stockpile_ros.runner.run_reconstruction`, :func:`~stockpile_ros.runner.run_segmentation`)
into the same work and result folders. No output bag is written: there is no stream to record.
"""

from __future__ import annotations

import dataclasses
import shutil
from dataclasses import dataclass, field
from pathlib import Path

from .artefacts import MeshInfo, SparseSummary, WorkFolder, load
from .components import result_lines
from .errors import CaptureError, StockpileError
from .recon.sources import source_kind
from .recon.stages import run_keyframes
from .result import Report
from .runner import Outcome, run_reconstruction, run_segmentation
from .runs import claim
from .segment.provenance import Provenance
from .settings import Settings, defaults, write_effective

__all__ = ['SourceSummary', 'replay_source', 'summary_lines']


@dataclass
class SourceSummary:
    """What a replay of photos or a video did and produced.

    Attributes:
        source: The photo folder or video file.
        kind: ``"photos"`` or ``"video"``.
        frames: Photos or video frames read.
        keyframes: Keyframes kept.
        decisions: Keyframe decisions by reason (rejections included).
        recon: The reconstruction's outcome, None when no keyframe was kept.
        outcome: The last stage's outcome.
        mesh: What the reconstruction says of its mesh, None when it did not get that far.
        report: The report, None when no result was produced.
        work_dir: Work folder.
        result_dir: Result folder.
        problems: What went wrong, one line each.

    """

    source: Path
    kind: str
    frames: int = 0
    keyframes: int = 0
    decisions: dict[str, int] = field(default_factory=dict)
    recon: Outcome | None = None
    outcome: Outcome | None = None
    mesh: MeshInfo | None = None
    report: Report | None = None
    work_dir: Path = Path()
    result_dir: Path = Path()
    problems: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        """Whether a result folder was produced."""
        return self.report is not None


def _failed(summary: SourceSummary, outcome: Outcome) -> SourceSummary:
    summary.outcome = outcome
    advice = f'. {outcome.advice}' if outcome.advice else ''
    summary.problems.append(f'{outcome.stage}: {outcome.reason}{advice}')
    return summary


def replay_source(
    source: str | Path,
    out: str | Path,
    settings: Settings,
    *,
    resume: bool = False,
    fresh: bool = False,
) -> SourceSummary:
    """Measure the rocks of a photo folder or a video into ``out``: ``work/`` and ``result/``.

    ``out`` is claimed as a bag replay claims it (:func:`stockpile_ros.runs.claim`): another
    source's or parameter set's run is refused, never added to.

    Args:
        source: Folder of photos (JPEG, PNG, HEIC, ...) or a video file.
        out: Output folder (created).
        settings: Parameters; ``work_dir`` is replaced by ``out/work``.
        resume: Continue the run of this source and parameters that ``out`` holds.
        fresh: Clear ``out`` and start over.

    Returns:
        The summary; ``ok`` is False when no result could be produced (reasons in ``problems``).

    Raises:
        StockpileError: ``source`` is a bag or neither photos nor a video, or ``out`` cannot
            take the run.

    """
    path = Path(source)
    kind = source_kind(path)
    if kind == 'bag':
        raise StockpileError(f'{path}: a bag; it is replayed through the components')
    out_dir = Path(out)
    settings = dataclasses.replace(settings, work_dir=out_dir / 'work')
    with claim(out_dir, path, settings.values, resume=resume, fresh=fresh) as run:
        summary = _measure(path, kind, out_dir, settings)
        if not summary.ok:
            run.state = 'failed'
    return summary


def _measure(path: Path, kind: str, out_dir: Path, settings: Settings) -> SourceSummary:
    work = WorkFolder(settings.work_dir)
    summary = SourceSummary(path, kind, work_dir=work.root, result_dir=out_dir / 'result')
    # A rerun writes the result anew: a failed one leaves none of an earlier run.
    shutil.rmtree(summary.result_dir, ignore_errors=True)
    write_effective(settings, settings.work_dir)
    try:
        counts = run_keyframes(path, work, settings.recon)
    except CaptureError as exc:
        return _failed(summary, Outcome(False, exc.stage, exc.reason, exc.advice))
    summary.frames, summary.keyframes = counts.frames, counts.keyframes
    summary.decisions = dict(counts.decisions)
    summary.recon = recon = run_reconstruction(settings)
    if not recon.ok:
        return _failed(summary, recon)
    summary.mesh = recon.mesh
    made_from = Provenance.for_input(path, settings.values, defaults())
    segmentation = run_segmentation(settings, work.mesh, summary.result_dir, made_from)
    if not segmentation.ok or segmentation.analysis is None:
        return _failed(summary, segmentation)
    summary.outcome = segmentation
    summary.report = segmentation.analysis.report
    write_effective(settings, summary.result_dir)
    return summary


def _registration(work: Path) -> list[str]:
    """Registration lines from ``sparse.json``: the model kept and what was left out, by name."""
    path = work / 'sparse' / 'sparse.json'
    if not path.exists():
        return []
    sparse = load(SparseSummary, path)
    lines = [f'intrinsics: {sparse.camera}']
    models = sparse.model_images
    lines.append(
        f'registered {sparse.registered}/{sparse.total} keyframes in the largest of '
        f'{len(models)} model(s), reprojection {sparse.mean_reprojection_error_px:.2f} px'
    )
    for number, model in enumerate(models[1:], start=2):
        names = model.photos or model.images
        lines.append(f'left out, model {number} ({model.registered}): {", ".join(names)}')
    lost = sparse.unregistered_photos or sparse.unregistered
    in_models = {n for m in models[1:] for n in m.photos or m.images}
    alone = [n for n in lost if n not in in_models]
    if alone:
        lines.append(f'registered in no model: {", ".join(alone)}')
    if sparse.matcher_note:
        lines.append(f'matching: {sparse.matcher_note}')
    return lines


def _scale_line(mesh: MeshInfo) -> str:
    scale = mesh.scale
    if not scale.metric:
        given = 'target' in mesh.scale_details
        why = 'the target was not seen in 3 registered views' if given else 'no target was given'
        return (
            f'scale: none: every size is in model units, not metres ({why}); put a printed '
            'marker in view and give it, e.g. --set recon.target=aruco:DICT_4X4_50:0:0.15'
        )
    return f'scale: {scale.summary()}'


def summary_lines(s: SourceSummary) -> tuple[list[str], list[str]]:
    """Return the summary ``stockpile replay`` prints: lines for stdout and for stderr."""
    out: list[str] = []
    err = [f'stockpile replay: {line}' for line in s.problems]
    what = 'photos' if s.kind == 'photos' else 'video frames'
    decisions = ', '.join(f'{k} {v}' for k, v in s.decisions.items() if v)
    out.append(f'{s.source}: {s.frames} {what}, {s.keyframes} keyframes'
               + (f' (decisions: {decisions})' if decisions else ''))  # fmt: skip
    out += _registration(s.work_dir)
    if s.mesh is not None:
        out.append(_scale_line(s.mesh))
    if s.report is not None:
        out += result_lines(s.report)
        out.append(f'result: {s.result_dir}')
    else:
        err.append('stockpile replay: no result: the capture could not be reconstructed and '
                   'segmented')  # fmt: skip
    out.append(f'work folder: {s.work_dir}')
    out.append('output bag: none (photos and video carry no ROS stream to record)')
    return out, err
