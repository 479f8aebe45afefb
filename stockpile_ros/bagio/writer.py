"""Write MCAP bags of standard and stockpile_msgs types."""

from __future__ import annotations

from pathlib import Path
from types import TracebackType
from typing import Any

from rosbags.interfaces import Connection
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys.store import Typestore

from ..messages import RosbagsFactory
from ..msgs import typestore

__all__ = ['BagWriter']


class BagWriter:
    """An MCAP bag writer that adds one connection per topic on first use.

    Message definitions are embedded in the MCAP file, so any rosbags reader decodes our types
    without being handed the ``.msg`` files.

    Example:
        >>> with BagWriter(path) as bag:  # doctest: +SKIP
        ...     bag.write('/camera/image_raw', msg, stamp_ns)

    Args:
        path: Bag folder to create; must not exist.
        store: Typestore to serialise with; the Jazzy store with our types by default.

    """

    def __init__(self, path: str | Path, store: Typestore | None = None):
        self.path = Path(path)
        self.store = store or typestore()
        self.factory = RosbagsFactory(self.store)
        self._writer = Writer(self.path, version=9, storage_plugin=StoragePlugin.MCAP)
        self._connections: dict[str, Connection] = {}

    def __enter__(self) -> BagWriter:
        self._writer.open()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self._writer.close()

    def write(self, topic: str, msg: Any, stamp_ns: int) -> None:
        """Serialise ``msg`` (a rosbags message) and write it on ``topic`` at ``stamp_ns``."""
        msgtype: str = msg.__msgtype__
        conn = self._connections.get(topic)
        if conn is None:
            conn = self._writer.add_connection(topic, msgtype, typestore=self.store)
            self._connections[topic] = conn
        elif conn.msgtype != msgtype:
            raise ValueError(f'topic {topic} already carries {conn.msgtype}, not {msgtype}')
        self._writer.write(conn, int(stamp_ns), self.store.serialize_cdr(msg, msgtype))
