"""Replay a recorded bag through the components of the node set: a bag driver, nothing more.

The bag's camera, camera info, odometry and transforms go, in bag order, into the same
:class:`~stockpile_ros.components.KeyframeComponent` the keyframe node runs (a PointCloud2 topic,
the odometry and the transforms into the reconstruction component, which accumulates the cloud);
what each component publishes is written into an MCAP bag and handed, as the very same message, to
the components that subscribe to it in the topic table (keyframes to the reconstruction, the surface
to the segmentation), as DDS would between the nodes. The reconstruction runs at every recorded
trigger (``std_msgs/Empty`` on the trigger topic), on its own after ``auto_trigger_keyframes``, or
once at the end of a bag that has no trigger. The input topics are written too (original stamps) so
that Foxglove shows the camera; results carry the stamp of their trigger.
"""

from __future__ import annotations

import dataclasses
import shutil
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .bagdrive import BagInputs, bag_inputs, drive
from .bagio.reader import BagReader, ReadStats
from .bagio.writer import PARTIAL_SUFFIX, BagWriter
from .components import KeyframeComponent, ReconstructionComponent, SegmentationComponent
from .result import Report
from .ros import topics
from .ros.publications import DIAGNOSTIC_PREFIX, Publication, diagnostics, status
from .runner import Outcome
from .runs import claim
from .segment.provenance import Provenance
from .settings import Settings, defaults, write_effective

__all__ = ['ReplaySummary', 'replay']

# Offered as transient local in the output bag, so that `ros2 bag play` republishes them latched.
_LATCHED_QOS = ('latched', 'status', 'tf_static')


@dataclass
class ReplaySummary:
    """What a replay did and produced.

    Attributes:
        bag: The input bag.
        image_topic: The camera topic replayed ('' when the bag has none).
        cloud_topic: The PointCloud2 topic replayed ('' when the bag has none).
        frames: Frames decoded and offered to the collector.
        skipped: Image messages that could not be used.
        keyframes: Keyframes held at the last trigger.
        coverage: Coverage at the last trigger.
        triggers: Pipeline runs (recorded triggers, or 1 for the end of the bag).
        camera_info: Whether keyframes had the intrinsics of a CameraInfo that fits their images
            (else they are self-calibrated).
        recon: The last reconstruction's outcome.
        outcome: The last run's final outcome (the segmentation's when the reconstruction ended
            well).
        report: The last report, None when no result was produced.
        work_dir: Work folder.
        result_dir: Result folder.
        output_bag: The output MCAP bag folder.
        problems: Diagnostics worth printing, one line each.

    """

    bag: Path
    image_topic: str
    cloud_topic: str = ''
    frames: int = 0
    skipped: int = 0
    keyframes: int = 0
    coverage: float = 0.0
    triggers: int = 0
    camera_info: bool = False
    recon: Outcome | None = None
    outcome: Outcome | None = None
    report: Report | None = None
    work_dir: Path = Path()
    result_dir: Path = Path()
    output_bag: Path = Path()
    problems: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        """Whether a result folder was produced."""
        return self.report is not None


def _problems(msg: Any) -> list[str]:
    """Return the WARN and ERROR lines of a ``DiagnosticArray``, as the summary prints them."""
    out = []
    for st in msg.status:
        if int(st.level):
            values = {kv.key: kv.value for kv in st.values}
            advice = f'. {values["advice"]}' if values.get('advice') else ''
            out.append(f'{st.name.removeprefix(DIAGNOSTIC_PREFIX + "/")}: {st.message}{advice}')
    return out


class _Rig:
    """The three components wired as the topic table says, publishing into the output bag."""

    def __init__(self, settings: Settings, writer: BagWriter, summary: ReplaySummary) -> None:
        self.settings = settings
        self.writer = writer
        self.summary = summary
        f = writer.factory
        self.keyframes = KeyframeComponent(settings, f)
        self.reconstruction = ReconstructionComponent(settings, f)
        self.segmentation = SegmentationComponent(settings, f)
        self._last_ns = 0
        self._waiting: int | None = None

    def publish(self, stamp_ns: int, publications: list[Publication]) -> None:
        """Write each publication and deliver it to its subscribers, in order."""
        self._last_ns = max(self._last_ns, stamp_ns)
        for name, msg in publications:
            self.writer.write(topics.absolute(name), msg, stamp_ns)
            if name == topics.DIAGNOSTICS:
                self.summary.problems.extend(_problems(msg))
            elif name == topics.KEYFRAMES:
                self.publish(stamp_ns, self.reconstruction.on_keyframe(msg, stamp_ns))
                if self._waiting is not None and not self.reconstruction.missing():
                    self._run(self._waiting)
            elif name == topics.KEYFRAME_STATUS:
                if self.reconstruction.on_keyframe_status(msg):
                    self.reconstruct(stamp_ns)
            elif name == topics.SURFACE:
                self.segment(stamp_ns, msg)

    def reconstruct(self, stamp_ns: int) -> None:
        """Run the reconstruction (a trigger); the surface it publishes is segmented in turn.

        As the live node does, it waits for the keyframes announced but still waiting for their
        odometry: it runs once the bag's next messages (or its end) have sent them.
        """
        if self.reconstruction.missing():
            self._waiting = stamp_ns
            return
        self._run(stamp_ns)

    def finish(self, last_ns: int) -> None:
        """At the end of the bag: run a trigger still waiting, or once if the bag had none."""
        if self._waiting is not None:
            self._run(self._waiting)
        elif self.summary.triggers == 0:
            self._run(last_ns)

    def _run(self, stamp_ns: int) -> None:
        self._waiting = None
        s = self.summary
        s.triggers += 1
        held = self.reconstruction.held
        s.keyframes, s.coverage = held.keyframes, held.coverage
        s.recon = s.outcome = self.reconstruction.run(
            self.settings, stamp_ns, lambda pubs: self.publish(stamp_ns, pubs)
        )

    def interrupted(self) -> None:
        """Close the output bag's story: the run was stopped, not finished."""
        f, held = self.writer.factory, self.reconstruction.held
        text = 'replay interrupted before it finished: no result'
        self.publish(self._last_ns, [
            diagnostics(f, self._last_ns, 'replay', 'ERROR', text),
            status(f, self._last_ns, 'FAILED', 'replay', held, text,
                   'Run it again with --resume to continue'),
        ])  # fmt: skip

    def segment(self, stamp_ns: int, surface: Any) -> None:
        failed = self.segmentation.on_surface(surface, stamp_ns)
        if failed:
            self.publish(stamp_ns, failed)
            return
        made_from = Provenance.for_input(self.summary.bag, self.settings.values, defaults())
        seg = self.segmentation.run(self.settings, stamp_ns,
                                    lambda pubs: self.publish(stamp_ns, pubs),
                                    self.summary.result_dir, made_from)  # fmt: skip
        self.summary.outcome = seg
        if seg.ok and seg.analysis:
            self.summary.report = seg.analysis.report
            write_effective(self.settings, self.summary.result_dir)


def replay(
    bag: str | Path,
    out: str | Path,
    settings: Settings,
    topic: str | None = None,
    *,
    resume: bool = False,
    fresh: bool = False,
) -> ReplaySummary:
    """Replay ``bag`` into ``out``: ``work/``, ``result/`` and the ``replay.mcap`` file.

    ``out`` is claimed for this bag and these parameters (``run.json``, see
    :mod:`stockpile_ros.runs`); a rerun writes ``replay.mcap`` and ``result/`` anew, so a failed
    one leaves neither of an earlier run.

    Args:
        bag: Input bag (folder, ``.mcap`` or ``.db3``).
        out: Output folder (created).
        settings: Parameters; ``work_dir`` is replaced by ``out/work``.
        topic: Image topic (default: the one with most messages).
        resume: Continue the run of this bag and parameters that ``out`` holds (the keyframes
            already kept are not selected again).
        fresh: Clear ``out`` and start over.

    Returns:
        The summary; ``ok`` is False when no result could be produced (the reasons are in
        ``problems`` and, as diagnostics, in the output bag).

    Raises:
        StockpileError: The bag cannot be opened or has no image topic; ``out`` is in use or
            holds another run (:func:`~stockpile_ros.runs.claim`).
        KeyboardInterrupt: Interrupted; the output bag, finalised as ``replay.mcap.partial``,
            ends with a FAILED status that says so, and ``run.json`` says ``interrupted``.

    """
    out_dir = Path(out)
    settings = dataclasses.replace(settings, work_dir=out_dir / 'work')
    # The bag is opened first: one that is not a bag is refused before a folder is claimed.
    with BagReader(bag) as reader:
        inputs = bag_inputs(reader, topic, settings.cloud.topic)
        with claim(out_dir, Path(bag), settings.values, resume=resume, fresh=fresh) as run:
            summary = _replay(reader, inputs, out_dir, settings)
            if not summary.ok:
                run.state = 'failed'
    return summary


def _replay(
    reader: BagReader, inputs: BagInputs, out_dir: Path, settings: Settings
) -> ReplaySummary:
    output_bag = out_dir / 'replay.mcap'
    summary = ReplaySummary(bag=reader.path, image_topic=inputs.image or '',
                            cloud_topic=inputs.cloud or '', work_dir=settings.work_dir,
                            result_dir=out_dir / 'result', output_bag=output_bag)  # fmt: skip
    partial = output_bag.with_name(output_bag.name + PARTIAL_SUFFIX)
    for stale in (output_bag, partial):
        stale.unlink(missing_ok=True)
    shutil.rmtree(summary.result_dir, ignore_errors=True)
    write_effective(settings, settings.work_dir)
    stats = ReadStats()
    latched = {topics.absolute(t.name) for t in topics.TABLE if t.qos in _LATCHED_QOS}
    with BagWriter(output_bag, latched=latched) as writer:
        rig = _Rig(settings, writer, summary)

        def passthrough(name: str, msg: Any, log_ns: int) -> None:
            try:
                writer.write(name, msg, log_ns)
            except (KeyError, ValueError, TypeError) as exc:
                stats.problems.append(f'{name}: not passed through ({exc})')

        try:
            last_ns = drive(reader, inputs, rig.keyframes, rig.publish, stats,
                            on_trigger=rig.reconstruct, on_input=passthrough,
                            clouds=rig.reconstruction)  # fmt: skip
            rig.finish(last_ns)
        except KeyboardInterrupt:
            rig.interrupted()
            raise
    kf = rig.keyframes
    summary.frames = kf.collector.state.frames
    summary.skipped = sum(kf.counts.skipped.values()) + stats.total_skipped
    summary.camera_info = kf.counts.with_camera > 0
    summary.problems.extend(stats.problems)
    return summary
