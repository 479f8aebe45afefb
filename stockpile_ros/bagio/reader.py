"""Read camera frames, camera models and odometry from ROS 2 bags (MCAP or sqlite3) with rosbags.

Both rosbag2 sqlite3 layouts are read (the newer one with embedded message definitions and the older
one with only the ``topics`` and ``messages`` tables); bags without embedded definitions decode with
the ROS 2 Jazzy typestore extended by our ``stockpile_msgs``.

Bad messages never end in a bare traceback: each becomes a :class:`~stockpile_ros.errors.BagError`
naming the bag, topic, message index (0-based within the topic) and what is wrong. With
``skip_bad=True`` the readers count it in a :class:`ReadStats` and carry on.
"""

from __future__ import annotations

import bisect
from collections.abc import Callable, Iterable, Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass, field
from pathlib import Path, PosixPath
from typing import Any, TypeVar

import numpy as np
import numpy.typing as npt
from rosbags.highlevel import AnyReader
from rosbags.interfaces import Connection

from ..camera import CameraModel, Frame
from ..errors import BagError
from ..ros.convert import CameraInfoError, camera_model_from_msg, message_stamp_ns
from ..ros.images import DEFAULT_MAX_PIXELS, ImageError, decode_image
from ..ros.typestore import typestore

__all__ = [
    'CAMERA_INFO_TOLERANCE_NS',
    'CAMERA_INFO_TYPE',
    'COMPRESSED_IMAGE_TYPE',
    'IMAGE_TYPE',
    'IMAGE_TYPES',
    'ODOMETRY_TYPE',
    'TF_TYPE',
    'BagReader',
    'PoseSample',
    'ReadStats',
    'camera_info_topic_for',
    'image_topics',
    'open_bag',
    'read_frames',
    'read_messages',
    'read_odometry',
]

IMAGE_TYPE = 'sensor_msgs/msg/Image'
COMPRESSED_IMAGE_TYPE = 'sensor_msgs/msg/CompressedImage'
IMAGE_TYPES = (IMAGE_TYPE, COMPRESSED_IMAGE_TYPE)
CAMERA_INFO_TYPE = 'sensor_msgs/msg/CameraInfo'
ODOMETRY_TYPE = 'nav_msgs/msg/Odometry'
TF_TYPE = 'tf2_msgs/msg/TFMessage'

CAMERA_INFO_TOLERANCE_NS = 500_000_000
"""Largest stamp difference between an image and the CameraInfo matched to it (0.5 s).

A CameraInfo topic whose messages all carry the same calibration matches at any time difference
(drivers that publish it once, latched).
"""

# image_transport puts the transport name after the base topic.
_TRANSPORT_SUFFIXES = ('compressed', 'compresseddepth', 'theora', 'zstd', 'ffmpeg')

T = TypeVar('T')


@dataclass
class ReadStats:
    """What a reader did, per topic.

    Attributes:
        read: Messages read from the bag.
        decoded: Messages turned into a usable result (deserialised and, for images, decoded).
        skipped: Messages skipped because they were bad.
        problems: One line per bad message, naming bag, topic, message index and what is wrong,
            plus notes that concern a whole topic (e.g. a CameraInfo that does not fit its images).

    """

    read: dict[str, int] = field(default_factory=dict)
    decoded: dict[str, int] = field(default_factory=dict)
    skipped: dict[str, int] = field(default_factory=dict)
    problems: list[str] = field(default_factory=list)

    def count_read(self, topic: str) -> None:
        """Count one message read on ``topic``."""
        self.read[topic] = self.read.get(topic, 0) + 1

    def count_decoded(self, topic: str) -> None:
        """Count one message of ``topic`` decoded."""
        self.decoded[topic] = self.decoded.get(topic, 0) + 1

    def count_skipped(self, error: BagError) -> None:
        """Count the bad message ``error`` describes as skipped and keep its description."""
        topic = error.topic or ''
        self.skipped[topic] = self.skipped.get(topic, 0) + 1
        self.problems.append(str(error))

    @property
    def total_skipped(self) -> int:
        """Messages skipped over all topics."""
        return sum(self.skipped.values())


@dataclass
class PoseSample:
    """One pose of the cart in the odometry frame.

    Attributes:
        stamp_ns: Stamp [ns] (header stamp; the bag time when the header stamp is zero).
        position: Position [m], shape (3,).
        orientation_xyzw: Unit quaternion x, y, z, w, shape (4,).
        frame_id: The fixed frame (usually ``odom``).
        child_frame_id: The moving frame (usually ``base_link``).

    """

    stamp_ns: int
    position: npt.NDArray[np.float64]
    orientation_xyzw: npt.NDArray[np.float64]
    frame_id: str
    child_frame_id: str


class _FolderPath(PosixPath):
    """A rosbag2 folder path that AnyReader must not take for a ROS 1 bag.

    AnyReader treats every path ending in ``.bag`` as a ROS 1 bag file; rosbag2 folders may be named
    so (the rosbag2 C++ test bags are).
    """

    @property
    def suffix(self) -> str:
        return ''


def _storage_path(bag: Path) -> Path:
    """Return the path to hand to rosbags; raise BagError saying why ``bag`` is no ROS 2 bag."""
    if not bag.exists():
        raise BagError(str(bag), 'no such file or folder')
    if bag.is_dir():
        if (bag / 'metadata.yaml').is_file():
            return _FolderPath(bag) if bag.suffix == '.bag' else bag
        stores = sorted([*bag.glob('*.mcap'), *bag.glob('*.db3')])
        if len(stores) == 1:
            # A bag folder whose metadata.yaml was lost: the single storage file still reads.
            return stores[0]
        raise BagError(
            str(bag),
            'not a rosbag2 folder: no metadata.yaml'
            + (f' and {len(stores)} storage files' if stores else ' and no .mcap or .db3 file'),
        )
    if bag.suffix in ('.mcap', '.db3'):
        return bag
    if bag.suffix == '.bag':
        raise BagError(str(bag), 'ROS 1 bags are not supported; convert it with rosbags-convert')
    raise BagError(
        str(bag),
        'not a ROS 2 bag: expected a bag folder (with metadata.yaml), an .mcap or a .db3 file',
    )


@contextmanager
def open_bag(bag: str | Path) -> Iterator[AnyReader]:
    """Open a ROS 2 bag (folder, ``.mcap`` or ``.db3`` file) for reading.

    Types come from the definitions embedded in the bag, or from the Jazzy typestore with our types
    when the bag has none (the older sqlite3 layout).

    Raises:
        BagError: The path does not exist, is not a ROS 2 bag, or cannot be opened.

    """
    path = Path(bag)
    reader = AnyReader([_storage_path(path)], default_typestore=typestore())
    try:
        reader.open()
    # rosbags reports unreadable bags through many exception types (YAML, sqlite, MCAP, OS errors).
    except Exception as exc:
        hint = ''
        if 'end magic' in str(exc):
            hint = ' (the MCAP file is truncated, e.g. a recording that was not closed; '
            hint += "'mcap recover' from the MCAP CLI rebuilds a readable file)"
        raise BagError(str(path), f'cannot open the bag: {exc}{hint}') from None
    try:
        yield reader
    finally:
        reader.close()


def _connections(reader: AnyReader, bag: Path, topics: Iterable[str]) -> list[Connection]:
    wanted = set(topics)
    missing = wanted - {c.topic for c in reader.connections}
    if missing:
        present = ', '.join(sorted({c.topic for c in reader.connections})) or 'none'
        raise BagError(str(bag), f'no topic {", ".join(sorted(missing))} (topics: {present})')
    return [c for c in reader.connections if c.topic in wanted]


def _decoded(
    reader: AnyReader,
    bag: Path,
    connections: list[Connection],
    convert: Callable[[Connection, int, Any], T],
    skip_bad: bool,
    stats: ReadStats,
) -> Iterator[tuple[Connection, int, int, T]]:
    """Deserialise and convert every message of ``connections``; bad ones raise or are skipped.

    Yields:
        connection, index within the topic, bag time [ns], converted message.

    """
    if not connections:
        return  # rosbags reads every topic when given no connection
    counters: dict[str, int] = {}
    messages = reader.messages(connections=connections)
    while True:
        try:
            item = next(messages, None)
        # A broken storage file cannot be read past; this ends the read whatever skip_bad says.
        except Exception as exc:
            where = ', '.join(f'{t}: {n} read' for t, n in counters.items()) or 'no message read'
            raise BagError(str(bag), f'the bag stops being readable ({where}): {exc}') from None
        if item is None:
            return
        conn, log_ns, raw = item
        index = counters.get(conn.topic, 0)
        counters[conn.topic] = index + 1
        stats.count_read(conn.topic)
        what = None
        try:
            msg = reader.deserialize(raw, conn.msgtype)
        # Truncated or foreign CDR fails in many ways inside rosbags; each is one bad message.
        except Exception as exc:
            what = f'cannot decode {conn.msgtype}: {str(exc) or type(exc).__name__}'
        else:
            try:
                value = convert(conn, log_ns, msg)
            except (ImageError, CameraInfoError) as exc:
                what = str(exc)
        if what is not None:
            error = BagError(str(bag), what, conn.topic, index)
            if not skip_bad:
                raise error
            stats.count_skipped(error)
            continue
        stats.count_decoded(conn.topic)
        yield conn, index, log_ns, value


def _topics_of(reader: AnyReader, msgtypes: Iterable[str]) -> list[tuple[str, int]]:
    """Topics carrying ``msgtypes`` with their message counts, most messages first."""
    kinds = set(msgtypes)
    counts: dict[str, int] = {}
    for conn in reader.connections:
        if conn.msgtype in kinds:
            counts[conn.topic] = counts.get(conn.topic, 0) + conn.msgcount
    return sorted(counts.items(), key=lambda item: (-item[1], item[0]))


def _base_topic(topic: str) -> str:
    """Strip an image_transport suffix: ``/cam/image_raw/compressed`` -> ``/cam/image_raw``."""
    head, _, last = topic.rstrip('/').rpartition('/')
    return head if last.lower() in _TRANSPORT_SUFFIXES and head else topic


def _namespace(topic: str) -> str:
    return topic.rstrip('/').rpartition('/')[0] or '/'


def camera_info_topic_for(image_topic: str, info_topics: Iterable[str]) -> str | None:
    """Return the CameraInfo topic in the image topic's namespace, if any.

    ``/cam/image_raw`` and ``/cam/image_raw/compressed`` both go with ``/cam/camera_info``.
    """
    namespace = _namespace(_base_topic(image_topic))
    same = sorted(t for t in info_topics if _namespace(t) == namespace)
    return same[0] if same else None


@dataclass
class _InfoSeries:
    stamps: list[int]
    models: list[CameraModel]

    @property
    def static(self) -> bool:
        first = self.models[0]
        return all(
            m.width == first.width
            and m.height == first.height
            and np.array_equal(m.k, first.k)
            and np.array_equal(m.d, first.d)
            for m in self.models[1:]
        )

    def nearest(self, stamp_ns: int) -> CameraModel | None:
        i = bisect.bisect_left(self.stamps, stamp_ns)
        best = min(
            (j for j in (i - 1, i) if 0 <= j < len(self.stamps)),
            key=lambda j: abs(self.stamps[j] - stamp_ns),
        )
        if abs(self.stamps[best] - stamp_ns) <= CAMERA_INFO_TOLERANCE_NS or self.static:
            return self.models[best]
        return None


class _CameraInfoIndex:
    """Every valid CameraInfo of a bag, by topic and by frame id, for matching frames."""

    def __init__(self, samples: list[tuple[str, int, CameraModel]]):
        samples = sorted(samples, key=lambda s: s[1])
        self.by_topic: dict[str, _InfoSeries] = {}
        self.by_frame: dict[str, _InfoSeries] = {}
        for topic, stamp, model in samples:
            for key, table in ((topic, self.by_topic), (model.frame_id, self.by_frame)):
                series = table.setdefault(key, _InfoSeries([], []))
                series.stamps.append(stamp)
                series.models.append(model)

    def match(self, image_topic: str, frame_id: str, stamp_ns: int) -> CameraModel | None:
        """CameraInfo of the image topic's namespace, else of the same frame id, nearest in time."""
        topic = camera_info_topic_for(image_topic, self.by_topic)
        series = self.by_topic.get(topic) if topic else self.by_frame.get(frame_id)
        return series.nearest(stamp_ns) if series else None


def _camera_infos(
    reader: AnyReader, bag: Path, skip_bad: bool, stats: ReadStats
) -> _CameraInfoIndex:
    conns = [c for c in reader.connections if c.msgtype == CAMERA_INFO_TYPE]
    samples: list[tuple[str, int, CameraModel]] = []
    if conns:
        for conn, _, _, (stamp, model) in _decoded(
            reader,
            bag,
            conns,
            lambda _c, t, m: (message_stamp_ns(m, t), camera_model_from_msg(m)),
            skip_bad,
            stats,
        ):
            samples.append((conn.topic, stamp, model))
    return _CameraInfoIndex(samples)


def _odometry_pose(msg: Any, log_ns: int) -> PoseSample:
    p, q = msg.pose.pose.position, msg.pose.pose.orientation
    return PoseSample(
        stamp_ns=message_stamp_ns(msg, log_ns),
        position=np.array([p.x, p.y, p.z], dtype=np.float64),
        orientation_xyzw=np.array([q.x, q.y, q.z, q.w], dtype=np.float64),
        frame_id=str(msg.header.frame_id),
        child_frame_id=str(msg.child_frame_id),
    )


def _tf_poses(msg: Any, log_ns: int, parent: str, child: str) -> list[PoseSample]:
    poses = []
    for tf in msg.transforms:
        if tf.header.frame_id.lstrip('/') != parent or tf.child_frame_id.lstrip('/') != child:
            continue
        t, q = tf.transform.translation, tf.transform.rotation
        poses.append(
            PoseSample(
                stamp_ns=message_stamp_ns(tf, log_ns),
                position=np.array([t.x, t.y, t.z], dtype=np.float64),
                orientation_xyzw=np.array([q.x, q.y, q.z, q.w], dtype=np.float64),
                frame_id=parent,
                child_frame_id=child,
            )
        )
    return poses


class BagReader:
    """An open ROS 2 bag; one opening serves many reads.

    Opening parses every message definition the bag embeds (about 0.4 s for a hundred types), so
    read several things through one :class:`BagReader` rather than through the module functions.

    Example:
        >>> with BagReader('bags/pile.mcap') as bag:  # doctest: +SKIP
        ...     frames = list(bag.frames())
        ...     poses = bag.odometry()

    Args:
        bag: Bag folder, ``.mcap`` or ``.db3`` file.

    Raises:
        BagError: (on entering) the path does not exist, is not a ROS 2 bag, or cannot be opened.

    """

    def __init__(self, bag: str | Path):
        self.path = Path(bag)
        self._stack = ExitStack()
        self._reader: AnyReader | None = None

    def __enter__(self) -> BagReader:
        self._reader = self._stack.enter_context(open_bag(self.path))
        return self

    def __exit__(self, *exc: object) -> None:
        self._reader = None
        self._stack.close()

    @property
    def reader(self) -> AnyReader:
        """The open rosbags reader."""
        if self._reader is None:
            raise RuntimeError('BagReader is not open; use it in a with statement')
        return self._reader

    def topics_of(self, msgtypes: Iterable[str]) -> list[tuple[str, int]]:
        """Return the topics carrying ``msgtypes`` with their message counts, most first."""
        return _topics_of(self.reader, msgtypes)

    def image_topics(self) -> list[str]:
        """Return the Image and CompressedImage topics, most messages first."""
        return [topic for topic, _ in self.topics_of(IMAGE_TYPES)]

    def messages(
        self, topics: Iterable[str], *, skip_bad: bool = True, stats: ReadStats | None = None
    ) -> Iterator[tuple[str, int, int, Any]]:
        """Deserialise every message of ``topics``; see :func:`read_messages`."""
        stats = stats if stats is not None else ReadStats()
        conns = _connections(self.reader, self.path, topics)
        for conn, index, log_ns, msg in _decoded(
            self.reader, self.path, conns, lambda _c, _t, m: m, skip_bad, stats
        ):
            yield conn.topic, index, log_ns, msg

    def frames_with_messages(
        self,
        topic: str | None = None,
        *,
        skip_bad: bool = True,
        stats: ReadStats | None = None,
        max_pixels: int = DEFAULT_MAX_PIXELS,
    ) -> Iterator[tuple[Frame, Any]]:
        """Like :meth:`frames`, yielding each frame with its deserialised message.

        For callers that need the message's own fields too (encoding, format).
        """
        stats = stats if stats is not None else ReadStats()
        reader, path = self.reader, self.path
        found = _topics_of(reader, IMAGE_TYPES)
        if topic is None:
            if not found:
                present = ', '.join(sorted({c.topic for c in reader.connections})) or 'none'
                raise BagError(str(path), f'no Image or CompressedImage topic (topics: {present})')
            topic = found[0][0]
        elif topic not in dict(found):
            names = ', '.join(t for t, _ in found) or 'none'
            raise BagError(
                str(path), f'{topic} is not an image topic in this bag (image topics: {names})'
            )
        infos = _camera_infos(reader, path, skip_bad, stats)
        conns = _connections(reader, path, [topic])
        mismatch_noted = False

        def convert(conn: Connection, log_ns: int, msg: Any) -> tuple[Frame, Any]:
            stamp = message_stamp_ns(msg, log_ns)
            frame_id = str(msg.header.frame_id)
            return Frame(stamp, decode_image(msg, max_pixels), frame_id, topic=conn.topic), msg

        for _, index, _, (frame, msg) in _decoded(reader, path, conns, convert, skip_bad, stats):
            frame.index = index
            camera = infos.match(frame.topic, frame.frame_id, frame.stamp_ns)
            if camera is not None and not camera.fits(frame.image):
                height, width = frame.image.shape[:2]
                if not mismatch_noted:
                    stats.problems.append(
                        f'{path}, topic {frame.topic}: CameraInfo is '
                        f'{camera.width}x{camera.height} but images are {width}x{height}; '
                        'such frames get no camera model'
                    )
                    mismatch_noted = True
                camera = None
            frame.camera = camera
            yield frame, msg

    def frames(
        self,
        topic: str | None = None,
        *,
        skip_bad: bool = True,
        stats: ReadStats | None = None,
        max_pixels: int = DEFAULT_MAX_PIXELS,
    ) -> Iterator[Frame]:
        """Yield the decoded frames of one image topic; see :func:`read_frames`."""
        items = self.frames_with_messages(
            topic, skip_bad=skip_bad, stats=stats, max_pixels=max_pixels
        )
        for frame, _ in items:
            yield frame

    def odometry(
        self,
        *,
        stats: ReadStats | None = None,
        parent_frame: str = 'odom',
        child_frame: str = 'base_link',
    ) -> list[PoseSample]:
        """Read the cart's odometry, sorted by stamp; see :func:`read_odometry`."""
        stats = stats if stats is not None else ReadStats()
        reader, path = self.reader, self.path
        odom = _topics_of(reader, [ODOMETRY_TYPE])
        if odom:
            conns = _connections(reader, path, [odom[0][0]])
            poses = [
                pose
                for _, _, _, pose in _decoded(
                    reader, path, conns, lambda _c, t, m: _odometry_pose(m, t), True, stats
                )
            ]
        else:
            conns = [c for c in reader.connections if c.topic == '/tf' and c.msgtype == TF_TYPE]
            poses = [
                pose
                for _, _, _, batch in _decoded(
                    reader,
                    path,
                    conns,
                    lambda _c, t, m: _tf_poses(m, t, parent_frame, child_frame),
                    True,
                    stats,
                )
                for pose in batch
            ]
        return sorted(poses, key=lambda p: p.stamp_ns)


def read_messages(
    bag: str | Path,
    topics: Iterable[str],
    *,
    skip_bad: bool = True,
    stats: ReadStats | None = None,
) -> Iterator[tuple[str, int, int, Any]]:
    """Deserialise every message of ``topics`` in bag-time order.

    Args:
        bag: Bag folder, ``.mcap`` or ``.db3`` file.
        topics: Topics to read; each must exist in the bag.
        skip_bad: Skip (and count) messages that cannot be deserialised instead of raising.
        stats: Filled with counts and problems when given.

    Yields:
        topic, index within the topic (0-based), bag time [ns], message (rosbags dataclass).

    Raises:
        BagError: (on iteration) the bag cannot be opened, a topic is missing, or
            (``skip_bad=False``) a message cannot be deserialised.

    """
    with BagReader(bag) as reader:
        yield from reader.messages(topics, skip_bad=skip_bad, stats=stats)


def image_topics(bag: str | Path) -> list[str]:
    """Return the Image and CompressedImage topics of a bag, most messages first.

    Raises:
        BagError: The bag cannot be opened.

    """
    with BagReader(bag) as reader:
        return reader.image_topics()


def read_frames(
    bag: str | Path,
    topic: str | None = None,
    *,
    skip_bad: bool = True,
    stats: ReadStats | None = None,
    max_pixels: int = DEFAULT_MAX_PIXELS,
) -> Iterator[Frame]:
    """Yield the decoded frames of one image topic, each with its matching camera model.

    A frame's camera is the CameraInfo of the image topic's namespace (``/cam/image_raw`` and
    ``/cam/image_raw/compressed`` go with ``/cam/camera_info``), or failing that of the same frame
    id, nearest in stamp within :data:`CAMERA_INFO_TOLERANCE_NS`; None when there is none or its
    size differs from the image's. Stamps are header stamps (the bag time when a header stamp is
    zero).

    Args:
        bag: Bag folder, ``.mcap`` or ``.db3`` file.
        topic: Image or CompressedImage topic; None picks the one with most messages.
        skip_bad: Skip (and count in ``stats``) messages that cannot be decoded instead of raising.
        stats: Filled with per-topic counts and problems when given.
        max_pixels: Largest ``width * height`` decoded; larger images are bad messages.

    Raises:
        BagError: (on iteration) the bag cannot be opened, has no such image topic, or
            (``skip_bad=False``) a message is bad; the error names bag, topic, index and what.

    """
    with BagReader(bag) as reader:
        yield from reader.frames(topic, skip_bad=skip_bad, stats=stats, max_pixels=max_pixels)


def read_odometry(
    bag: str | Path,
    *,
    stats: ReadStats | None = None,
    parent_frame: str = 'odom',
    child_frame: str = 'base_link',
) -> list[PoseSample]:
    """Read the cart's odometry, sorted by stamp.

    Uses the ``nav_msgs/Odometry`` topic with most messages; without one, the ``/tf`` transforms
    from ``parent_frame`` to ``child_frame``. Bad messages are skipped and counted in ``stats``.

    Returns:
        The poses; empty when the bag has neither source.

    Raises:
        BagError: The bag cannot be opened or read.

    """
    with BagReader(bag) as reader:
        return reader.odometry(stats=stats, parent_frame=parent_frame, child_frame=child_frame)
