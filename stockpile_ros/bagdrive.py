"""A recorded bag driven through the keyframe component, as the live topics would feed it.

Both ``stockpile replay`` and the keyframe stage of ``stockpile reconstruct BAG`` go this way, so
a bag gives the keyframes (odometry interpolated, camera from the CameraInfo of the stamp) that
the keyframe node would have sent live.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .artefacts import KeyframeSummary, WorkFolder
from .bagio.reader import BagReader, ReadStats, camera_info_topic_for
from .components import KeyframeComponent, ReconstructionComponent
from .errors import CaptureError, StockpileError
from .progress import progress
from .recon.options import ReconOptions
from .recon.sources import source_kind
from .recon.stages import run_keyframes
from .ros import topics
from .ros.messages import RosbagsFactory
from .ros.publications import Publication
from .ros.typestore import typestore
from .settings import Settings

__all__ = ['BagInputs', 'bag_inputs', 'collect_keyframes', 'drive', 'keyframes_from_bag']

_INFO = 'sensor_msgs/msg/CameraInfo'
_TF = 'tf2_msgs/msg/TFMessage'
_EMPTY = 'std_msgs/msg/Empty'
_ODOMETRY = 'nav_msgs/msg/Odometry'


@dataclass(frozen=True)
class BagInputs:
    """The topics of a bag that feed the node set.

    Attributes:
        image: The camera topic.
        info: Its CameraInfo topic, None when the bag has none.
        odometry: The odometry topic, None when the bag has none.
        tf: ``/tf`` and ``/tf_static`` where the bag has them.
        triggers: Recorded triggers (``std_msgs/Empty`` on the trigger topic).

    """

    image: str
    info: str | None
    odometry: str | None
    tf: tuple[str, ...]
    triggers: tuple[str, ...]

    def routes(self) -> dict[str, str]:
        """Return what each topic is, by name."""
        out = {t: t for t in self.tf} | {t: 'trigger' for t in self.triggers}
        out[self.image] = 'image'
        if self.info:
            out[self.info] = 'info'
        if self.odometry:
            out[self.odometry] = 'odometry'
        return out


def bag_inputs(reader: BagReader, topic: str | None = None) -> BagInputs:
    """Find a bag's inputs; ``topic`` picks the camera (default: the one with most messages).

    Raises:
        StockpileError: No image topic, or ``topic`` is not one.

    """
    images = reader.image_topics()
    if topic is None and not images:
        raise StockpileError(f'{reader.path}: no Image or CompressedImage topic to replay')
    image = topic or images[0]
    if image not in images:
        raise StockpileError(
            f'{image} is not an image topic of {reader.path} (image topics: '
            f'{", ".join(images) or "none"})'
        )
    odometry = [t for t, _ in reader.topics_of([_ODOMETRY])]
    return BagInputs(
        image=image,
        info=camera_info_topic_for(image, [t for t, _ in reader.topics_of([_INFO])]),
        odometry=odometry[0] if odometry else None,
        tf=tuple(t for t, _ in reader.topics_of([_TF]) if t in (topics.TF, topics.TF_STATIC)),
        triggers=tuple(
            t for t, _ in reader.topics_of([_EMPTY]) if t.rstrip('/').endswith(topics.TRIGGER)
        ),
    )


def drive(
    reader: BagReader,
    inputs: BagInputs,
    keyframes: KeyframeComponent,
    publish: Callable[[int, list[Publication]], None],
    stats: ReadStats,
    *,
    on_trigger: Callable[[int], None] | None = None,
    on_input: Callable[[str, Any, int], None] | None = None,
) -> int:
    """Feed the bag's inputs to ``keyframes`` in bag order.

    Args:
        reader: The open bag.
        inputs: Its inputs (:func:`bag_inputs`).
        keyframes: The component fed.
        publish: Receives what the component publishes, with the log time it happened at.
        stats: Read statistics (skipped messages and why).
        on_trigger: Called at each recorded trigger with its log time.
        on_input: Called with every input message before it is fed (to record it).

    Returns:
        The last message's log time.

    """
    routes = inputs.routes()
    counts = reader.reader.topics
    total = sum(counts[t].msgcount for t in routes if t in counts) or None
    last_ns = 0
    messages = reader.messages(list(routes), stats=stats)
    for name, _, log_ns, msg in progress(messages, 'bag', total=total, unit='msg'):
        last_ns = log_ns
        route = routes[name]
        if route == 'trigger':
            if on_trigger is not None:
                on_trigger(log_ns)
            continue
        if on_input is not None:
            on_input(name, msg, log_ns)
        if route == 'image':
            publish(log_ns, keyframes.on_image(msg, log_ns))
        elif route == 'info':
            publish(log_ns, keyframes.on_camera_info(msg, log_ns))
        elif route == 'odometry':
            publish(log_ns, keyframes.on_odometry(msg, log_ns))
        else:
            publish(log_ns, keyframes.on_tf(msg, route == topics.TF_STATIC, log_ns))
    # The end of the recording: nothing more will complete the keyframes still waiting.
    publish(last_ns, keyframes.flush(last_ns))
    return last_ns


def keyframes_from_bag(bag: Path, settings: Settings, topic: str | None = None) -> KeyframeSummary:
    """Select a bag's keyframes into the work folder's ``keyframes/``, as the nodes would.

    The keyframe component keeps its selection in ``capture/`` and hands each keyframe, as a
    message, to the reconstruction component, which writes ``keyframes/``.

    Returns:
        Counts: frames seen, keyframes held (in total and new), decisions by reason.

    Raises:
        CaptureError: No keyframe was kept.

    """
    f = RosbagsFactory(typestore())
    selector = KeyframeComponent(settings, f)
    held = ReconstructionComponent(settings, f)
    before = held.held.keyframes

    def publish(log_ns: int, publications: list[Publication]) -> None:
        for name, msg in publications:
            if name == topics.KEYFRAMES:
                held.on_keyframe(msg, log_ns)

    stats = ReadStats()
    with BagReader(bag) as reader:
        drive(reader, bag_inputs(reader, topic), selector, publish, stats)
    state = selector.collector.state
    count = held.held.keyframes
    if count == 0:
        raise CaptureError(
            'keyframes',
            f'no keyframe was kept out of {state.frames} frames (rejections: {state.decisions})',
            'Check that the source holds sharp images of the pile',
        )
    return KeyframeSummary(state.frames, count, count - before, dict(state.decisions),
                           stats.problems)  # fmt: skip


def collect_keyframes(
    settings: Settings,
) -> Callable[[Path, WorkFolder, ReconOptions], KeyframeSummary]:
    """Return the keyframe stage of ``stockpile reconstruct``: bags as the nodes take them.

    Args:
        settings: Parameters (their ``recon`` and work folder are replaced by the stage's).

    """

    def stage(source: Path, work: WorkFolder, options: ReconOptions) -> KeyframeSummary:
        if source_kind(source) != 'bag':
            return run_keyframes(source, work, options)
        here = dataclasses.replace(settings, work_dir=work.root, recon=options)
        return keyframes_from_bag(source, here, options.topic)

    return stage
