"""What a bag holds and what is wrong with it: the core of ``stockpile info``."""

from __future__ import annotations

import sqlite3
from contextlib import closing
from dataclasses import asdict, dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from ..progress import progress
from ..ros.images import describe_encoding
from .reader import (
    CAMERA_INFO_TYPE,
    IMAGE_TYPES,
    ODOMETRY_TYPE,
    BagReader,
    ReadStats,
    camera_info_topic_for,
)

__all__ = ['BagSummary', 'ImageTopicSummary', 'TopicSummary', 'format_summary', 'summarize']


@dataclass
class ImageTopicSummary:
    """What decoding every message of one image topic found.

    Attributes:
        decoded: Messages decoded into images.
        bad: Messages that could not be decoded (see the bag's problems).
        sizes: Distinct image sizes, ``"WxH"``.
        encodings: Distinct Image encodings or CompressedImage formats of the decoded messages.
        camera_info: The CameraInfo topic of the image topic's namespace, None if there is none
            (frames may still match a CameraInfo by frame id).
        with_camera: Decoded frames that got a camera model.
        frame_rate_hz: Mean rate of the decoded frames from their stamps; None below two frames.

    """

    decoded: int = 0
    bad: int = 0
    sizes: list[str] = field(default_factory=list)
    encodings: list[str] = field(default_factory=list)
    camera_info: str | None = None
    with_camera: int = 0
    frame_rate_hz: float | None = None


@dataclass
class TopicSummary:
    """One topic: its type, message count and, for image topics, what decoding found."""

    name: str
    msgtype: str
    count: int
    image: ImageTopicSummary | None = None


@dataclass
class BagSummary:
    """Everything ``stockpile info`` reports.

    Attributes:
        path: The bag as given.
        storage: ``"mcap"`` or ``"sqlite3"``.
        layout: For sqlite3, which rosbag2 schema the database uses; None for MCAP.
        message_count: Messages in the bag.
        start_ns: Bag time of the first message, None for an empty bag.
        end_ns: Bag time of the last message, None for an empty bag.
        duration_s: ``end - start`` [s].
        topics: Every topic, sorted by name.
        odometry: Where odometry comes from (topic and type, or ``/tf odom->base_link``), or None.
        odometry_poses: Poses read from that source.
        problems: One line per bad message or mismatch found.
        decoded_images: Whether every image message was decoded (``False`` with ``decode=False``).

    """

    path: str
    storage: str
    layout: str | None
    message_count: int
    start_ns: int | None
    end_ns: int | None
    duration_s: float
    topics: list[TopicSummary]
    odometry: str | None
    odometry_poses: int
    problems: list[str]
    decoded_images: bool

    def to_dict(self) -> dict[str, Any]:
        """Return the summary as plain JSON-ready data."""
        return asdict(self)


def _storage_files(path: Path) -> list[Path]:
    """List the bag's storage files (``.mcap``, ``.db3``, possibly ``.zstd`` compressed)."""
    files = [path] if path.is_file() else sorted(path.iterdir())
    return [p for p in files if {'.mcap', '.db3'} & set(p.suffixes)]


def _sqlite_layout(db: Path) -> str | None:
    """Tell the rosbag2 sqlite3 schemas apart by their tables."""
    try:
        with closing(sqlite3.connect(f'file:{db}?mode=ro', uri=True)) as con:
            rows = con.execute("SELECT name FROM sqlite_master WHERE type='table'").fetchall()
    except sqlite3.Error:
        return None
    tables = {str(row[0]) for row in rows}
    if 'message_definitions' in tables or 'schema' in tables:
        return 'newer rosbag2 layout (' + ', '.join(sorted(tables)) + ')'
    return 'older rosbag2 layout (' + ', '.join(sorted(tables)) + ')'


def _image_summary(
    bag: BagReader,
    topic: str,
    count: int,
    info_topics: list[str],
    decode: bool,
    problems: list[str],
) -> ImageTopicSummary:
    summary = ImageTopicSummary(camera_info=camera_info_topic_for(topic, info_topics))
    if not decode:
        return summary
    stats = ReadStats()
    sizes: dict[str, None] = {}
    encodings: dict[str, None] = {}
    stamps = []
    items = bag.frames_with_messages(topic, stats=stats)
    for frame, msg in progress(items, desc=f'decoding {topic}', total=count, unit='msg'):
        height, width = frame.image.shape[:2]
        sizes[f'{width}x{height}'] = None
        encodings[describe_encoding(msg)] = None
        stamps.append(frame.stamp_ns)
        summary.with_camera += frame.camera is not None
    summary.decoded = stats.decoded.get(topic, 0)
    summary.bad = stats.skipped.get(topic, 0)
    summary.sizes = list(sizes)
    summary.encodings = list(encodings)
    if len(stamps) >= 2 and max(stamps) > min(stamps):
        summary.frame_rate_hz = (len(stamps) - 1) / ((max(stamps) - min(stamps)) / 1e9)
    problems.extend(p for p in stats.problems if p not in problems)
    return summary


def summarize(bag: str | Path, *, decode: bool = True) -> BagSummary:
    """Summarise a bag, decoding every image message (with a progress bar) unless told not to.

    Args:
        bag: Bag folder, ``.mcap`` or ``.db3`` file.
        decode: Decode every image message to find bad ones, sizes, encodings, camera matches.

    Raises:
        BagError: The bag cannot be opened or stops being readable.

    """
    path = Path(bag)
    with BagReader(path) as opened:
        reader = opened.reader
        count = reader.message_count
        start_ns = reader.start_time if count else None
        # rosbags' end_time lies one nanosecond after the last message.
        end_ns = reader.end_time - 1 if count else None
        topics = [
            TopicSummary(name, info.msgtype or 'mixed types', info.msgcount)
            for name, info in sorted(reader.topics.items())
        ]
        info_topics = [t.name for t in topics if t.msgtype == CAMERA_INFO_TYPE]
        problems: list[str] = []
        for topic in topics:
            if topic.msgtype in IMAGE_TYPES:
                topic.image = _image_summary(
                    opened, topic.name, topic.count, info_topics, decode, problems
                )
        odom_stats = ReadStats()
        poses = opened.odometry(stats=odom_stats)
    problems.extend(odom_stats.problems)
    files = _storage_files(path)
    storage = 'mcap' if files and '.mcap' in files[0].suffixes else 'sqlite3'
    layout = _sqlite_layout(files[0]) if files and files[0].suffix == '.db3' else None
    odom_topics = sorted((t for t in topics if t.msgtype == ODOMETRY_TYPE), key=lambda t: -t.count)
    if odom_topics:
        odometry: str | None = f'{odom_topics[0].name} (nav_msgs/Odometry)'
    else:
        odometry = '/tf odom->base_link' if poses else None
    return BagSummary(
        path=str(path),
        storage=storage,
        layout=layout,
        message_count=count,
        start_ns=start_ns,
        end_ns=end_ns,
        duration_s=(end_ns - start_ns) / 1e9
        if start_ns is not None and end_ns is not None
        else 0.0,
        topics=topics,
        odometry=odometry,
        odometry_poses=len(poses),
        problems=problems,
        decoded_images=decode,
    )


def _time(ns: int | None) -> str:
    if ns is None:
        return '-'
    utc = datetime.fromtimestamp(ns / 1e9, tz=timezone.utc)
    return f'{utc:%Y-%m-%d %H:%M:%S}.{ns % 10**9 // 10**6:03d} UTC ({ns} ns)'


def _image_line(img: ImageTopicSummary, count: int, decoded: bool) -> str:
    parts = []
    if decoded:
        parts.append(f'{img.decoded}/{count} decoded')
        if img.sizes:
            parts.append('size ' + ', '.join(img.sizes))
        if img.encodings:
            parts.append('encoding ' + ', '.join(img.encodings))
        if img.frame_rate_hz is not None:
            parts.append(f'{img.frame_rate_hz:.2f} Hz')
    info = img.camera_info or 'none in its namespace'
    camera = f'camera_info {info}'
    if decoded:
        camera += f' (camera model on {img.with_camera}/{img.decoded} frames)'
    parts.append(camera)
    return '; '.join(parts)


def format_summary(summary: BagSummary) -> str:
    """Render a summary as the text ``stockpile info`` prints."""
    lines = [
        f'bag:       {summary.path}',
        f'storage:   {summary.storage}' + (f', {summary.layout}' if summary.layout else ''),
        f'messages:  {summary.message_count}',
        f'start:     {_time(summary.start_ns)}',
        f'end:       {_time(summary.end_ns)}',
        f'duration:  {summary.duration_s:.3f} s',
        f'topics:    {len(summary.topics)}',
    ]
    width = max((len(t.name) for t in summary.topics), default=0)
    type_width = max((len(t.msgtype) for t in summary.topics), default=0)
    for topic in summary.topics:
        lines.append(f'  {topic.name:<{width}}  {topic.msgtype:<{type_width}}  {topic.count:>6}')
        if topic.image is not None:
            line = _image_line(topic.image, topic.count, summary.decoded_images)
            lines.append(f'  {"":<{width}}    {line}')
    if summary.odometry:
        lines.append(f'odometry:  {summary.odometry}, {summary.odometry_poses} poses')
    else:
        lines.append('odometry:  none (no nav_msgs/Odometry topic, no /tf odom->base_link)')
    if not summary.decoded_images:
        lines.append('problems:  not checked (images not decoded)')
    elif summary.problems:
        lines.append(f'problems:  {len(summary.problems)}')
        lines.extend(f'  - {p}' for p in summary.problems)
    else:
        lines.append('problems:  none')
    return '\n'.join(lines)
