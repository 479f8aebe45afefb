"""Write MCAP bags of standard and stockpile_msgs types.

A path ending in ``.mcap`` becomes one MCAP file, the layout ``ros2 bag play``, Foxglove and the
MCAP tools open directly; any other path becomes a rosbag2 bag folder (``metadata.yaml`` plus one
MCAP file), the layout ``stockpile simulate`` writes. Both hold the same MCAP content:

- message definitions embedded (``ros2msg`` schemas with the full concatenated definition text),
  so any reader decodes our types without being handed the ``.msg`` files;
- each topic's offered QoS in its channel's metadata under ``offered_qos_profiles`` (a YAML
  string, as rosbag2's MCAP storage writes it) and in the embedded rosbag2 metadata: latched topics
  as transient local, reliable, keep last 1, so that ``ros2 bag play`` republishes them latched;
  all others volatile and reliable;
- chunks compressed with zstd.

rosbags writes all of that; this module only adds the single-file layout and the rule that no
final path appears unless the writing ended cleanly.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Iterable
from contextlib import suppress
from pathlib import Path
from types import TracebackType
from typing import Any

from rosbags.interfaces import (
    Connection,
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer
from rosbags.typesys.store import Typestore

from ..ros.messages import RosbagsFactory
from ..ros.typestore import typestore

__all__ = ['LATCHED_QOS', 'PARTIAL_SUFFIX', 'VOLATILE_QOS', 'BagWriter']

PARTIAL_SUFFIX = '.partial'
"""Appended to the path for what a ``with`` block that raised had written (finalised, readable)."""

# Zero durations are rmw's "default", which DDS takes as infinite: what an rclpy QoSProfile built
# without deadline, lifespan or lease gives, as our nodes build theirs.
_DEFAULT_TIME = QosTime(sec=0, nsec=0)

VOLATILE_QOS = Qos(
    history=QosHistory.KEEP_LAST,
    depth=10,
    reliability=QosReliability.RELIABLE,
    durability=QosDurability.VOLATILE,
    deadline=_DEFAULT_TIME,
    lifespan=_DEFAULT_TIME,
    liveliness=QosLiveliness.AUTOMATIC,
    liveliness_lease_duration=_DEFAULT_TIME,
    avoid_ros_namespace_conventions=False,
)
"""QoS recorded as offered for topics that are not latched (rclpy's default profile, depth 10)."""

LATCHED_QOS = VOLATILE_QOS._replace(depth=1, durability=QosDurability.TRANSIENT_LOCAL)
"""QoS recorded as offered for latched topics: the nodes' ``LATCHED`` profile."""


class BagWriter:
    """An MCAP bag writer that adds one connection per topic on first use.

    Nothing appears at ``path`` until the ``with`` block ends cleanly: the bag is written under a
    hidden temporary folder beside it (``.<name>.<random>.tmp``) and renamed into place once
    finalised. When the block raises (``KeyboardInterrupt`` included), what was written is still
    finalised but renamed to ``<path>.partial`` (replacing an older one), so that an interrupted
    run never leaves a valid-looking final bag yet keeps what it had; rename it to read it. A
    process killed outright leaves only the temporary folder.

    Example:
        >>> with BagWriter(out / 'replay.mcap', latched={'/tf_static'}) as bag:  # doctest: +SKIP
        ...     bag.write('/camera/image_raw', msg, stamp_ns)

    Args:
        path: ``.mcap`` file to create, or (any other name) rosbag2 bag folder to create; must
            not exist. Missing parent folders are created.
        store: Typestore to serialise with; the Jazzy store with our types by default.
        latched: Absolute names of the topics offered as transient local (latched); every other
            topic is recorded as volatile.

    Raises:
        FileExistsError: ``path`` exists (checked here and again before the final rename).
        ValueError: A latched topic name is not absolute.

    """

    def __init__(
        self,
        path: str | Path,
        store: Typestore | None = None,
        latched: Iterable[str] = frozenset(),
    ):
        self.path = Path(path)
        if self.path.exists():
            raise FileExistsError(f'{self.path} exists already, not overwriting')
        self.latched = frozenset(latched)
        relative = sorted(t for t in self.latched if not t.startswith('/'))
        if relative:
            raise ValueError(f'latched topics must be absolute names: {", ".join(relative)}')
        self.store = store or typestore()
        self.factory = RosbagsFactory(self.store)
        self.single_file = self.path.suffix == '.mcap'
        self._tmp: Path | None = None
        self._writer: Writer | None = None
        self._connections: dict[str, Connection] = {}

    @property
    def partial_path(self) -> Path:
        """Where a ``with`` block that raised leaves what it wrote: ``<path>.partial``."""
        return self.path.with_name(self.path.name + PARTIAL_SUFFIX)

    def __enter__(self) -> BagWriter:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._tmp = Path(
            tempfile.mkdtemp(prefix=f'.{self.path.name}.', suffix='.tmp', dir=self.path.parent)
        )
        # rosbags names the storage file after its folder (``<folder>/<folder>.mcap``) and records
        # that name in the metadata it embeds: pick the folder name that makes it the final name.
        folder = self._tmp / (self.path.stem if self.single_file else self.path.name)
        writer = Writer(folder, version=9, storage_plugin=StoragePlugin.MCAP)
        # STORAGE mode compresses each MCAP chunk, which is what rosbag2's MCAP storage does;
        # the FILE and MESSAGE modes would wrap the file or each message instead.
        writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
        # rosbags would otherwise record custom_data as null, and rosbag2 reads that field as a
        # string map: give it a map.
        writer.set_custom_data('writer', 'stockpile_ros')
        try:
            writer.open()
        except BaseException:
            shutil.rmtree(self._tmp, ignore_errors=True)
            raise
        self._writer = writer
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        writer, tmp = self._writer, self._tmp
        self._writer, self._tmp = None, None
        if writer is None or tmp is None:
            return
        try:
            if exc_type is None:
                writer.close()
                self._move(writer.path, self.path)
            else:
                # The original exception is what the caller needs to see; a failure to save the
                # partial bag on top of it would only hide it.
                with suppress(Exception):
                    writer.close()
                    partial = self.partial_path
                    if partial.is_dir():
                        shutil.rmtree(partial)
                    self._move(writer.path, partial, replace=True)
        finally:
            shutil.rmtree(tmp, ignore_errors=True)

    def _move(self, folder: Path, target: Path, *, replace: bool = False) -> None:
        """Rename the finalised bag (the storage file, or the whole folder) to ``target``."""
        source = folder / f'{folder.name}.mcap' if self.single_file else folder
        if not replace and target.exists():
            raise FileExistsError(f'{target} appeared while writing; the bag was not saved')
        os.replace(source, target)

    def write(self, topic: str, msg: Any, stamp_ns: int) -> None:
        """Serialise ``msg`` (a rosbags message) and write it on ``topic`` at ``stamp_ns``.

        Raises:
            RuntimeError: The writer is not open (use it in a ``with`` statement).
            ValueError: ``topic`` already carries another message type.

        """
        if self._writer is None:
            raise RuntimeError('BagWriter is not open; use it in a with statement')
        msgtype: str = msg.__msgtype__
        conn = self._connections.get(topic)
        if conn is None:
            qos = LATCHED_QOS if topic in self.latched else VOLATILE_QOS
            conn = self._writer.add_connection(
                topic, msgtype, typestore=self.store, offered_qos_profiles=[qos]
            )
            self._connections[topic] = conn
        elif conn.msgtype != msgtype:
            raise ValueError(f'topic {topic} already carries {conn.msgtype}, not {msgtype}')
        self._writer.write(conn, int(stamp_ns), self.store.serialize_cdr(msg, msgtype))
