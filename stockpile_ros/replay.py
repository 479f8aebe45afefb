"""Replay a recorded bag through the components of the node set, as the nodes would run on it.

Frames go, in bag order, through the keyframe collector (odometry interpolated at each frame);
the pipeline runs at every recorded trigger (``std_msgs/Empty`` on the trigger topic), or once at
the end of the bag when it has none. Everything the nodes would publish is written into an MCAP
bag, next to the camera images, camera info and transforms of the input (original stamps) so that
Foxglove shows the camera too; results carry the stamp of their trigger.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from . import topics
from .bagio.images import ImageError, decode_image
from .bagio.reader import (
    BagReader,
    CameraInfoError,
    ReadStats,
    camera_info_topic_for,
    camera_model_from_msg,
    message_stamp_ns,
)
from .bagio.writer import BagWriter
from .camera import CameraModel, Frame
from .errors import StockpileError
from .progress import progress
from .publish import (
    Publication,
    capture_warnings,
    diagnostics,
    keyframe_status,
    reconstruction_diagnostics,
    reconstruction_outputs,
    segmentation_outputs,
    status,
)
from .recon.collector import KeyframeCollector
from .recon.pipeline import WorkFolder
from .recon.sources import OdometryTrack
from .runner import Outcome, run_reconstruction, run_segmentation
from .settings import Settings

__all__ = ['ReplaySummary', 'replay']

_INFO = 'sensor_msgs/msg/CameraInfo'
_TF = 'tf2_msgs/msg/TFMessage'
_EMPTY = 'std_msgs/msg/Empty'
_ODOMETRY = 'nav_msgs/msg/Odometry'


@dataclass
class ReplaySummary:
    """What a replay did and produced.

    Attributes:
        bag: The input bag.
        image_topic: The camera topic replayed.
        frames: Frames decoded and offered to the collector.
        skipped: Image messages that could not be used.
        keyframes: Keyframes held at the last trigger.
        coverage: Coverage at the last trigger.
        triggers: Pipeline runs (recorded triggers, or 1 for the end of the bag).
        camera_info: Whether the bag had usable camera info (else intrinsics are self-calibrated).
        recon: The last reconstruction's outcome.
        outcome: The last run's final outcome (the segmentation's when the reconstruction ended
            well).
        report: The last report.json dict, None when no result was produced.
        work_dir: Work folder.
        result_dir: Result folder.
        output_bag: The output MCAP bag folder.
        problems: Diagnostics worth printing, one line each.

    """

    bag: Path
    image_topic: str
    frames: int = 0
    skipped: int = 0
    keyframes: int = 0
    coverage: float = 0.0
    triggers: int = 0
    camera_info: bool = False
    recon: Outcome | None = None
    outcome: Outcome | None = None
    report: dict[str, Any] | None = None
    work_dir: Path = Path()
    result_dir: Path = Path()
    output_bag: Path = Path()
    problems: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        """Whether a result folder was produced."""
        return self.report is not None


def _absolute(topic: str) -> str:
    return topic if topic.startswith('/') else '/' + topic


class _Replay:
    """State of one replay: collector, writer, summary."""

    def __init__(self, settings: Settings, writer: BagWriter, summary: ReplaySummary) -> None:
        self.settings = settings
        self.writer = writer
        self.f = writer.factory
        self.summary = summary
        self.collector = KeyframeCollector(
            WorkFolder(settings.work_dir).keyframes,
            settings.recon.selector,
            float(settings.values['coverage_full_parallax']),
        )
        self.max_faces = int(settings.values['display_max_faces'])

    def emit(self, stamp_ns: int, publications: list[Publication]) -> None:
        for topic, msg in publications:
            self.writer.write(_absolute(topic), msg, stamp_ns)

    def problem(self, stamp_ns: int, name: str, level: str, text: str, **values: Any) -> None:
        self.summary.problems.append(text)
        self.emit(stamp_ns, [diagnostics(self.f, stamp_ns, name, level, text, values)])

    def run_pipeline(self, stamp_ns: int) -> None:
        """Reconstruct and segment what the collector holds; results stamped ``stamp_ns``."""
        f, state, s = self.f, self.collector.state, self.summary
        s.triggers += 1
        s.keyframes, s.coverage = state.keyframes, state.coverage

        def on_stage(stage: str, index: int, seconds: float | None) -> None:
            if seconds is None:
                self.emit(stamp_ns, [status(f, stamp_ns, 'RECONSTRUCTING', stage, state,
                                            f'running {stage}', progress=index / 3)])  # fmt: skip

        recon = run_reconstruction(self.settings, on_stage)
        self.emit(stamp_ns, reconstruction_diagnostics(f, stamp_ns, recon))
        s.recon = s.outcome = recon
        if not recon.ok:
            s.problems.append(f'{recon.stage}: {recon.reason}. {recon.advice}')
            self.emit(stamp_ns, [status(f, stamp_ns, 'FAILED', recon.stage, state,
                                        recon.reason, recon.advice)])  # fmt: skip
            return
        work = self.settings.work_dir
        self.emit(stamp_ns, reconstruction_outputs(f, stamp_ns, work, self.settings.frame_id,
                                                   self.max_faces))  # fmt: skip
        ready = f.cls('std_msgs/msg/String')(data=str(work))
        self.emit(stamp_ns, [(topics.MESH_READY, ready)])
        self.emit(stamp_ns, [status(f, stamp_ns, 'SEGMENTING', 'segment', state, 'segmenting')])
        seg = run_segmentation(self.settings, s.result_dir)
        s.outcome = seg
        if not seg.ok or seg.analysis is None:
            s.problems.append(f'{seg.stage}: {seg.reason}. {seg.advice}')
            self.emit(stamp_ns, [
                diagnostics(f, stamp_ns, 'segment', 'ERROR', seg.reason, {'advice': seg.advice}),
                status(f, stamp_ns, 'FAILED', 'segment', state, seg.reason, seg.advice),
            ])  # fmt: skip
            return
        report = seg.analysis.report
        s.report = report
        s.problems.extend(report['warnings'])
        self.emit(stamp_ns, capture_warnings(f, stamp_ns, report))
        self.emit(
            stamp_ns,
            segmentation_outputs(f, stamp_ns, seg.analysis, self.settings.frame_id, self.max_faces),
        )
        self.emit(stamp_ns, [
            diagnostics(f, stamp_ns, 'segment', 'OK', f'{len(report["rocks"])} rocks',
                        {'rocks': len(report['rocks']), 'seconds': round(seg.seconds['segment'], 2),
                         'd50': report['gradation'].get('d50')}),
            status(f, stamp_ns, 'DONE', 'segment', state, _verdict(report)),
        ])  # fmt: skip


def _verdict(report: dict[str, Any]) -> str:
    g = report['gradation']
    d50 = 'undefined' if g.get('d50') is None else f'{g["d50"]:.3f} m'
    text = f'{len(report["rocks"])} rocks, D50 {d50}'
    spec = g.get('spec') or {}
    if spec.get('checked'):
        text += f'; class {spec.get("class")}: ' + ('PASS' if spec.get('passed') else 'FAIL')
    return text


def replay(
    bag: str | Path, out: str | Path, settings: Settings, topic: str | None = None
) -> ReplaySummary:
    """Replay ``bag`` into ``out``: ``work/``, ``result/`` and the ``replay.mcap`` bag folder.

    Args:
        bag: Input bag (folder, ``.mcap`` or ``.db3``).
        out: Output folder (created; must not hold a previous ``replay.mcap``).
        settings: Parameters; ``work_dir`` is replaced by ``out/work``.
        topic: Image topic (default: the one with most messages).

    Returns:
        The summary; ``ok`` is False when no result could be produced (the reasons are in
        ``problems`` and, as diagnostics, in the output bag).

    Raises:
        StockpileError: The bag cannot be opened, has no image topic, or ``out`` holds a replay.

    """
    out_dir = Path(out)
    output_bag = out_dir / 'replay.mcap'
    if output_bag.exists():
        raise StockpileError(f'{output_bag} exists already; choose another --out or remove it')
    out_dir.mkdir(parents=True, exist_ok=True)
    settings = dataclasses.replace(settings, work_dir=out_dir / 'work')
    summary = ReplaySummary(bag=Path(bag), image_topic='', work_dir=settings.work_dir,
                            result_dir=out_dir / 'result', output_bag=output_bag)  # fmt: skip
    stats = ReadStats()
    with BagReader(bag) as reader:
        images = reader.image_topics()
        if topic is None and not images:
            raise StockpileError(f'{bag}: no Image or CompressedImage topic to replay')
        image_topic = topic or images[0]
        if image_topic not in images:
            raise StockpileError(
                f'{image_topic} is not an image topic of {bag} (image topics: '
                f'{", ".join(images) or "none"})'
            )
        summary.image_topic = image_topic
        info_topic = camera_info_topic_for(image_topic, [t for t, _ in reader.topics_of([_INFO])])
        passthrough = [t for t, _ in reader.topics_of([_TF, _ODOMETRY])]
        trigger_topics = [
            t for t, _ in reader.topics_of([_EMPTY]) if t.rstrip('/').endswith(topics.TRIGGER)
        ]
        passthrough += [info_topic] if info_topic else []
        wanted = [image_topic, *passthrough, *trigger_topics]
        counts = reader.reader.topics
        total = sum(counts[t].msgcount for t in wanted if t in counts) or None
        with BagWriter(output_bag) as writer:
            state = _Replay(settings, writer, summary)
            _stream(reader, state, stats, (image_topic, info_topic), wanted, trigger_topics, total)
    summary.skipped += stats.total_skipped
    summary.problems.extend(stats.problems)
    return summary


def _stream(
    reader: BagReader,
    state: _Replay,
    stats: ReadStats,
    camera_topics: tuple[str, str | None],
    wanted: list[str],
    trigger_topics: list[str],
    total: int | None,
) -> None:
    """Pass the ``wanted`` topics through, in order, running the pipeline at each trigger."""
    image_topic, info_topic = camera_topics
    summary, f, settings = state.summary, state.f, state.settings
    camera: CameraModel | None = None
    odometry: OdometryTrack | None = None
    odometry_read = False
    last_ns = 0
    bad_info_noted = False
    bad_encodings: dict[str, int] = {}
    if info_topic is None:
        state.problem(
            0,
            'camera_info',
            'WARN',
            f'no CameraInfo for {image_topic}: the intrinsics are self-calibrated by SfM',
        )
    messages = reader.messages(wanted, stats=stats)
    for topic, _, log_ns, msg in progress(messages, 'replay', total=total, unit='msg'):
        last_ns = log_ns
        if topic in trigger_topics:
            state.run_pipeline(log_ns)
            continue
        try:
            state.writer.write(topic, msg, log_ns)
        except (KeyError, ValueError, TypeError) as exc:
            stats.problems.append(f'{topic}: not passed through ({exc})')
        if topic == info_topic:
            try:
                camera = camera_model_from_msg(msg)
                summary.camera_info = True
            except CameraInfoError as exc:
                camera = None
                if not bad_info_noted:
                    state.problem(log_ns, 'camera_info', 'WARN',
                                  f'{topic}: {exc}; such frames are self-calibrated')  # fmt: skip
                    bad_info_noted = True
            continue
        if topic != image_topic:
            continue
        try:
            image = decode_image(msg)
        except ImageError as exc:
            summary.skipped += 1
            key = str(exc)
            if key not in bad_encodings:
                state.problem(log_ns, 'camera', 'ERROR', f'{topic}: frame skipped: {exc}')
            bad_encodings[key] = bad_encodings.get(key, 0) + 1
            continue
        frame_id = str(msg.header.frame_id)
        stamp_ns = message_stamp_ns(msg, log_ns)
        usable = camera if camera is not None and camera.fits(image) else None
        frame = Frame(stamp_ns, image, frame_id, usable, topic, summary.frames)
        summary.frames += 1
        if settings.recon.use_odometry and not odometry_read:
            odometry = OdometryTrack.from_bag(reader.path, usable.frame_id if usable else frame_id)
            odometry_read = True
        pose = None if odometry is None else odometry.at(stamp_ns)
        state.collector.push(frame, pose)
        state.emit(log_ns, [keyframe_status(f, log_ns, state.collector.state)])
    if bad_encodings:
        counts = '; '.join(f'{n} x {why}' for why, n in bad_encodings.items())
        state.problem(last_ns, 'camera', 'ERROR', f'{summary.skipped} frames skipped: {counts}')
    if not trigger_topics or summary.triggers == 0:
        state.run_pipeline(last_ns)
