"""Play a recorded bag into live nodes, without rosbag2 (not on PyPI) and without rclpy here.

The node layer (:mod:`stockpile_ros.nodes.player`) only creates the publishers; everything that
walks a bag lives here so that it runs, and is tested, without ROS:

- :func:`to_message` turns a rosbags message into an instance of a message class of the caller's
  choosing (the rclpy class, in the player), field by field, from the class's own field table;
- :func:`timed_messages` yields a bag's messages at their recorded pace (or a multiple of it);
- :func:`input_topics` picks the bag topics that feed the node set's inputs (:data:`topics.TABLE`);
- :func:`play` and :func:`wait_until` are the loops the player runs.
"""

from __future__ import annotations

import argparse
import array
import math
import re
import time
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .bagio.reader import BagReader, ReadStats
from .ros import topics

__all__ = [
    'INPUTS',
    'PlayStats',
    'input_topics',
    'parse_mapping',
    'play',
    'timed_messages',
    'to_message',
    'wait_until',
]

# rosidl_generator_py stores these element types of sequences as array.array (with this type
# code) and of fixed-size arrays as numpy arrays (with this dtype); the setters take either as is.
_NUMERIC: dict[str, tuple[str, type[np.generic]]] = {
    'float': ('f', np.float32),
    'double': ('d', np.float64),
    'int8': ('b', np.int8),
    'uint8': ('B', np.uint8),
    'int16': ('h', np.int16),
    'uint16': ('H', np.uint16),
    'int32': ('i', np.int32),
    'uint32': ('I', np.uint32),
    'int64': ('q', np.int64),
    'uint64': ('Q', np.uint64),
}
_FLOATS = frozenset({'float', 'double', 'long double'})

# 'sequence<T>', 'sequence<T, N>' (bounded) and 'T[N]' (fixed size), as get_fields_and_field_types
# spells them; T itself is a basic type, '[w]string[<N>]' or 'pkg/Name'.
_SEQUENCE = re.compile(r'^sequence<(?P<element>[^,>]+(?:<\d+>)?)(?:,\s*(?P<bound>\d+))?>$')
_ARRAY = re.compile(r'^(?P<element>.+)\[(?P<size>\d+)\]$')

INPUTS: tuple[topics.Topic, ...] = tuple(
    t for t in topics.TABLE if not t.publishers or t.qos in ('tf', 'tf_static')
)
"""The table entries a bag feeds: those no component publishes, and /tf and /tf_static.

The tf topics are shared by every broadcaster: the reconstruction adds the stockpile frame to
/tf_static, yet the camera mount and the odometry transforms the keyframe node needs come from
the recording.
"""

Resolve = Callable[[str], Any]
_Convert = Callable[[Any], Any]

# Conversion plans per (message class, resolver): built once, so that a bag of thousands of
# messages of a few types parses each field table once.
_PLANS: dict[tuple[Any, Resolve], list[tuple[str, _Convert]]] = {}


def to_message(cls: Any, src: Any, resolve: Resolve) -> Any:
    """Build an instance of ``cls`` with the fields of ``src``, recursively.

    ``cls`` is a generated message class (rclpy's, say); ``src`` a message with the same field
    names, as rosbags deserialises them (numpy arrays for primitive arrays). Primitive sequences
    become ``array.array`` copied from the source's buffer in one go (a several-megabyte image
    costs a memory copy, never a Python list), fixed-size arrays numpy arrays, ``octet`` fields
    ``bytes`` of length 1.

    Args:
        cls: Target class; it must have ``get_fields_and_field_types()`` (rosidl-generated
            classes do).
        src: Source message.
        resolve: Returns the class of a nested type given as ``pkg/msg/Name``
            (:func:`stockpile_ros.nodes.interfaces.get_message`).

    Returns:
        The new ``cls`` instance.

    Raises:
        ValueError: ``src`` lacks a field of ``cls``, a fixed-size array has the wrong length,
            a bounded sequence is too long, or a field type is not understood.

    """
    return _message(cls, resolve)(src)


def _message(cls: Any, resolve: Resolve) -> _Convert:
    """Return the converter of whole messages to ``cls``."""
    key = (cls, resolve)
    plan = _PLANS.get(key)
    if plan is None:
        plan = [
            (name, _converter(spelled, resolve, f'{cls.__name__}.{name}'))
            for name, spelled in cls.get_fields_and_field_types().items()
        ]
        _PLANS[key] = plan
    name_of = cls.__name__

    def convert(src: Any) -> Any:
        values = {}
        for name, conv in plan:
            try:
                value = getattr(src, name)
            except AttributeError:
                raise ValueError(
                    f'{type(src).__name__} has no field {name!r} of {name_of}'
                ) from None
            values[name] = conv(value)
        return cls(**values)

    return convert


def _converter(spelled: str, resolve: Resolve, where: str) -> _Convert:
    """Return the converter of one field whose type ``get_fields_and_field_types`` spells so."""
    if (match := _SEQUENCE.match(spelled)) is not None:
        bound = int(match['bound']) if match['bound'] else None
        return _sequence(match['element'].strip(), bound, resolve, where)
    if (match := _ARRAY.match(spelled)) is not None:
        return _fixed_array(match['element'], int(match['size']), resolve, where)
    return _element(spelled, resolve, where)


def _element(spelled: str, resolve: Resolve, where: str) -> _Convert:
    """Return the converter of a single value of type ``spelled``."""
    if '/' in spelled:
        package, _, name = spelled.rpartition('/')
        # Nested types are spelled 'pkg/Name'; message classes are found under 'pkg/msg/Name'.
        full = spelled if package.endswith('/msg') else f'{package}/msg/{name}'
        holder: list[_Convert] = []

        def nested(value: Any) -> Any:
            # Resolved on first use: a field table is parsed only when a message needs it.
            if not holder:
                holder.append(_message(resolve(full), resolve))
            return holder[0](value)

        return nested
    if spelled in _FLOATS:
        return float
    if spelled in _NUMERIC:
        return int
    if spelled == 'boolean':
        return bool
    if spelled == 'octet':
        return _octet
    if spelled == 'char':
        return _char
    if re.fullmatch(r'w?string(<\d+>)?', spelled):
        return str
    raise ValueError(f'{where}: field type {spelled!r} is not understood')


def _octet(value: Any) -> bytes:
    """Return one byte as rclpy wants an ``octet`` (rosbags gives an int)."""
    if isinstance(value, (bytes, bytearray)):
        return bytes(value)
    return bytes((int(value),))


def _char(value: Any) -> str:
    """Return one character as rclpy wants a ``char`` (rosbags gives an int)."""
    return value if isinstance(value, str) else chr(int(value))


def _sequence(element: str, bound: int | None, resolve: Resolve, where: str) -> _Convert:
    """Return the converter of a sequence (``bound``: its largest length, None: unbounded)."""

    def check(n: int) -> None:
        if bound is not None and n > bound:
            raise ValueError(f'{where}: {n} values, more than the bound {bound}')

    if element in _NUMERIC:
        code, dtype = _NUMERIC[element]

        def numeric(value: Any) -> array.array[Any]:
            flat = np.ascontiguousarray(value, dtype=dtype).reshape(-1)
            check(flat.size)
            out = array.array(code)
            # One memory copy from the numpy buffer (itself often a view of the bag's chunk).
            out.frombytes(flat.data.cast('B'))
            return out

        return numeric
    return _one_by_one(element, resolve, where, check)


def _fixed_array(element: str, size: int, resolve: Resolve, where: str) -> _Convert:
    """Return the converter of a fixed-size array of ``size`` values."""

    def check(n: int) -> None:
        if n != size:
            raise ValueError(f'{where}: {n} values, the type holds exactly {size}')

    if element in _NUMERIC:
        _, dtype = _NUMERIC[element]

        def numeric(value: Any) -> np.ndarray[Any, Any]:
            # A copy: the message must not keep the bag's buffer alive, nor share it.
            out = np.array(value, dtype=dtype).reshape(-1)
            check(out.size)
            return out

        return numeric
    return _one_by_one(element, resolve, where, check)


def _one_by_one(
    element: str, resolve: Resolve, where: str, check: Callable[[int], None]
) -> _Convert:
    """Return the converter of an array of octets, strings or messages (a Python value each)."""
    if element == 'octet':

        def octets(value: Any) -> list[bytes]:
            raw = bytes(np.ascontiguousarray(value, dtype=np.uint8).reshape(-1))
            check(len(raw))
            return [raw[i : i + 1] for i in range(len(raw))]

        return octets
    one = _element(element, resolve, where)

    def items(value: Any) -> list[Any]:
        check(len(value))
        return [one(v) for v in value]

    return items


def timed_messages(
    bag: BagReader | str | Path,
    topic_names: Iterable[str],
    rate: float = 1.0,
    start: float | None = None,
    *,
    stats: ReadStats | None = None,
    clock: Callable[[], float] = time.monotonic,
    sleep: Callable[[float], None] = time.sleep,
) -> Iterator[tuple[str, str, Any]]:
    """Yield the messages of ``topic_names`` in log-time order, each at its recorded offset.

    The first message is due at ``start``; each later one at ``start`` plus its log time's offset
    from the first, divided by ``rate``. A message that is already late is yielded at once: the
    schedule is kept, so a slow consumer catches up instead of shifting everything after it.
    Messages with the same log time come in the bag's storage order, the same on every run.

    Args:
        bag: An open :class:`BagReader`, or a bag path (opened for the iteration).
        topic_names: Bag topics to read; each must be in the bag.
        rate: Speed-up over the recording (1: real time, 2: twice as fast); ``<= 0`` or
            infinite: as fast as possible.
        start: ``clock()`` value at which the first message is due; None: when it is read.
        stats: Filled with read counts and skipped (undecodable) messages when given.
        clock: Monotonic clock in seconds.
        sleep: Sleeps for the given seconds.

    Yields:
        topic, message type (``pkg/msg/Name``), message (rosbags dataclass).

    Raises:
        ValueError: ``rate`` is NaN.
        BagError: (on iteration) the bag cannot be opened or a topic is missing.

    """
    if math.isnan(rate):
        raise ValueError('rate is NaN')
    paced = 0 < rate < math.inf
    wanted = list(topic_names)
    if isinstance(bag, BagReader):
        yield from _paced(bag, wanted, rate if paced else 0.0, start, stats, clock, sleep)
        return
    with BagReader(bag) as reader:
        yield from _paced(reader, wanted, rate if paced else 0.0, start, stats, clock, sleep)


def _paced(
    reader: BagReader,
    wanted: list[str],
    rate: float,
    start: float | None,
    stats: ReadStats | None,
    clock: Callable[[], float],
    sleep: Callable[[float], None],
) -> Iterator[tuple[str, str, Any]]:
    """Run the loop of :func:`timed_messages` (``rate`` 0: no pacing)."""
    first: tuple[int, float] | None = None  # log time of the first message, when it is due
    for topic, _, log_ns, msg in reader.messages(wanted, stats=stats):
        if rate > 0:
            if first is None:
                first = (log_ns, clock() if start is None else start)
            delay = first[1] + (log_ns - first[0]) / 1e9 / rate - clock()
            if delay > 0:
                sleep(delay)
        yield topic, msg.__msgtype__, msg


def wait_until(
    condition: Callable[[], bool],
    timeout: float,
    *,
    period: float = 0.05,
    clock: Callable[[], float] = time.monotonic,
    sleep: Callable[[float], None] = time.sleep,
) -> bool:
    """Poll ``condition`` every ``period`` seconds until it holds or ``timeout`` seconds passed.

    Returns:
        Whether ``condition`` held (it is checked once more at the deadline).

    """
    deadline = clock() + timeout
    while not condition():
        left = deadline - clock()
        if left <= 0:
            return condition()
        sleep(min(period, left))
    return True


def parse_mapping(pair: str) -> tuple[str, str]:
    """Parse ``BAG_TOPIC=TABLE_TOPIC`` (the player's ``--map``) into its two names.

    Raises:
        argparse.ArgumentTypeError: Not two non-empty names around ``=``.

    """
    bag_topic, sep, name = pair.partition('=')
    if not sep or not bag_topic or not name:
        raise argparse.ArgumentTypeError(f'expected BAG_TOPIC=TABLE_TOPIC, got {pair!r}')
    return bag_topic, name


def input_topics(
    bag_topics: Mapping[str, str], mapping: Mapping[str, str] | None = None
) -> dict[str, topics.Topic]:
    """Pick the bag topics that feed inputs of the node set (see :data:`INPUTS`).

    A bag topic feeds the input with the same absolute name; ``mapping`` sends other bag topics
    (or the same ones) to inputs named by the table instead, so no ROS remapping is needed to
    play a bag recorded under other names.

    Args:
        bag_topics: Message type (``pkg/msg/Name``) by bag topic.
        mapping: Table topic name (relative or absolute) by bag topic.

    Returns:
        The table entry to publish on, by bag topic, in the bag topics' sorted order.

    Raises:
        ValueError: A mapped bag topic is not in the bag, a mapped name is no input of the node
            set, the types differ, or two bag topics would feed one input.

    """
    inputs = {topics.absolute(t.name): t for t in INPUTS}
    chosen: dict[str, topics.Topic] = {}
    for bag_topic in sorted(bag_topics):
        entry = inputs.get(topics.absolute(bag_topic))
        if entry is not None and entry.msgtype == bag_topics[bag_topic]:
            chosen[bag_topic] = entry
    for bag_topic, name in sorted((mapping or {}).items()):
        if bag_topic not in bag_topics:
            raise ValueError(f'{bag_topic} is not a topic of the bag')
        entry = inputs.get(topics.absolute(name))
        if entry is None:
            names = ', '.join(sorted(inputs))
            raise ValueError(f'{name} is not an input of the node set (inputs: {names})')
        if entry.msgtype != bag_topics[bag_topic]:
            raise ValueError(
                f'{bag_topic} carries {bag_topics[bag_topic]}, {entry.name} takes {entry.msgtype}'
            )
        chosen[bag_topic] = entry
    # A bag topic of the input's own name that was mapped elsewhere still feeds its own input;
    # two bag topics on one input would interleave two streams, so that is refused.
    targets: dict[str, str] = {}
    for bag_topic, entry in chosen.items():
        other = targets.setdefault(entry.name, bag_topic)
        if other != bag_topic:
            raise ValueError(f'{other} and {bag_topic} would both be published on {entry.name}')
    return dict(sorted(chosen.items()))


@dataclass
class PlayStats:
    """What :func:`play` published.

    Attributes:
        published: Messages published per bag topic.
        seconds: Wall-clock time from the first message to the end.
        read: The bag reader's counts (skipped messages and their reasons included).

    """

    published: dict[str, int] = field(default_factory=dict)
    seconds: float = 0.0
    read: ReadStats = field(default_factory=ReadStats)

    @property
    def total(self) -> int:
        """Messages published over all topics."""
        return sum(self.published.values())


def play(
    bag: BagReader | str | Path,
    topic_names: Iterable[str],
    publish: Callable[[str, str, Any], None],
    rate: float = 1.0,
    *,
    clock: Callable[[], float] = time.monotonic,
    sleep: Callable[[float], None] = time.sleep,
) -> PlayStats:
    """Hand every message of ``topic_names`` to ``publish(topic, msgtype, msg)`` at its time.

    See :func:`timed_messages` for ``rate`` and the order.

    Raises:
        BagError: The bag cannot be opened or a topic is missing.

    """
    stats = PlayStats()
    began = clock()
    for topic, msgtype, msg in timed_messages(
        bag, topic_names, rate, began, stats=stats.read, clock=clock, sleep=sleep
    ):
        publish(topic, msgtype, msg)
        stats.published[topic] = stats.published.get(topic, 0) + 1
    stats.seconds = clock() - began
    return stats
