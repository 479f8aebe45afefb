"""Bag playback without ROS: pacing, order, which bag topics feed the node set."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import pytest

from stockpile_ros.bagio.writer import BagWriter
from stockpile_ros.playback import input_topics, parse_mapping, play, timed_messages, wait_until
from stockpile_ros.ros import messages as m
from stockpile_ros.ros.messages import RosbagsFactory
from stockpile_ros.ros.typestore import typestore

F = RosbagsFactory(typestore())
T0 = 1_700_000_000_000_000_000


def _odom(stamp_ns: int, x: float) -> object:
    return m.odometry(F, stamp_ns, [x, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0])


@pytest.fixture
def bag(tmp_path: Path) -> Path:
    """Three odometry messages 0.2 s apart, written out of order, plus a trigger in between."""
    path = tmp_path / 'three.mcap'
    with BagWriter(path) as writer:
        writer.write('/odom', _odom(T0 + 400_000_000, 2.0), T0 + 400_000_000)
        writer.write('/odom', _odom(T0, 0.0), T0)
        writer.write('/stockpile/trigger', F.cls('std_msgs/msg/Empty')(), T0 + 300_000_000)
        writer.write('/odom', _odom(T0 + 200_000_000, 1.0), T0 + 200_000_000)
    return path


def _xs(items: list[tuple[str, str, object]]) -> list[object]:
    return [msg.pose.pose.position.x if t == '/odom' else t for t, _, msg in items]  # type: ignore[attr-defined]


def test_real_rate_keeps_the_recorded_offsets(bag: Path) -> None:
    began = time.monotonic()
    arrivals = []
    items = []
    for item in timed_messages(bag, ['/odom', '/stockpile/trigger'], rate=1.0):
        arrivals.append(time.monotonic() - began)
        items.append(item)
    total = time.monotonic() - began
    assert _xs(items) == [0.0, 1.0, '/stockpile/trigger', 2.0]  # log-time order
    assert [mt for _, mt, _ in items] == [
        'nav_msgs/msg/Odometry',
        'nav_msgs/msg/Odometry',
        'std_msgs/msg/Empty',
        'nav_msgs/msg/Odometry',
    ]
    assert total >= 0.4
    # Each one no earlier than its offset (the bag opening comes before the first).
    offsets = [0.0, 0.2, 0.3, 0.4]
    assert all(a >= o - 0.01 + arrivals[0] for a, o in zip(arrivals, offsets, strict=True))


@pytest.mark.parametrize('rate', [0.0, -1.0, float('inf')])
def test_unpaced_rates_never_sleep(bag: Path, rate: float) -> None:
    slept: list[float] = []
    items = list(timed_messages(bag, ['/odom'], rate=rate, sleep=slept.append))
    assert slept == []
    assert _xs(items) == [0.0, 1.0, 2.0]


def test_rate_divides_the_offsets_and_start_sets_the_first_due_time(bag: Path) -> None:
    now = [100.0]
    slept: list[float] = []

    def sleep(seconds: float) -> None:
        slept.append(seconds)
        now[0] += seconds

    items = list(
        timed_messages(bag, ['/odom'], rate=2.0, start=101.0, clock=lambda: now[0], sleep=sleep)
    )
    assert _xs(items) == [0.0, 1.0, 2.0]
    assert slept == pytest.approx([1.0, 0.1, 0.1])  # due at 101.0, 101.1, 101.2


def test_a_late_consumer_catches_up_instead_of_shifting_the_schedule(bag: Path) -> None:
    now = [0.0]
    slept: list[float] = []

    def sleep(seconds: float) -> None:
        slept.append(seconds)
        now[0] += seconds

    for i, _ in enumerate(
        timed_messages(bag, ['/odom'], start=0.0, clock=lambda: now[0], sleep=sleep)
    ):
        if i == 0:
            now[0] += 0.3  # the consumer spends 0.3 s on the first message
    assert slept == pytest.approx([0.1])  # the second is late (0.2) and goes at once


def test_order_is_the_same_on_every_run(bag: Path) -> None:
    topics = ['/stockpile/trigger', '/odom']
    first = _xs(list(timed_messages(bag, topics, rate=0)))
    assert first == _xs(list(timed_messages(bag, topics, rate=0)))


def test_nan_rate_is_refused(bag: Path) -> None:
    with pytest.raises(ValueError, match='NaN'):
        next(timed_messages(bag, ['/odom'], rate=float('nan')))


def test_play_counts_what_it_published(bag: Path) -> None:
    seen: list[tuple[str, str]] = []
    stats = play(bag, ['/odom', '/stockpile/trigger'], lambda t, mt, _: seen.append((t, mt)), 0)
    assert stats.published == {'/odom': 3, '/stockpile/trigger': 1}
    assert stats.total == 4 == len(seen)
    assert seen[2] == ('/stockpile/trigger', 'std_msgs/msg/Empty')


def test_input_topics_match_absolute_names_and_types() -> None:
    bag_topics = {
        '/camera/image_raw': 'sensor_msgs/msg/Image',
        '/camera/camera_info': 'sensor_msgs/msg/CameraInfo',
        '/odom': 'nav_msgs/msg/Odometry',
        '/tf': 'tf2_msgs/msg/TFMessage',
        '/tf_static': 'tf2_msgs/msg/TFMessage',
        '/stockpile/trigger': 'std_msgs/msg/Empty',
        '/stockpile/keyframes': 'stockpile_msgs/msg/Keyframe',  # an output: not replayed
        '/diagnostics': 'diagnostic_msgs/msg/DiagnosticArray',
        '/camera/image_raw/compressed': 'sensor_msgs/msg/Image',  # wrong type: not replayed
    }
    chosen = input_topics(bag_topics)
    assert {b: e.name for b, e in chosen.items()} == {
        '/camera/camera_info': 'camera/camera_info',
        '/camera/image_raw': 'camera/image_raw',
        '/odom': 'odom',
        '/stockpile/trigger': 'stockpile/trigger',
        '/tf': '/tf',
        '/tf_static': '/tf_static',
    }
    assert {e.qos for e in chosen.values()} == {'sensor', 'pose', 'tf', 'tf_static', 'reliable'}


def test_input_topics_mapping() -> None:
    bag_topics = {'/zed/left/image': 'sensor_msgs/msg/Image', '/odom': 'nav_msgs/msg/Odometry'}
    chosen = input_topics(bag_topics, {'/zed/left/image': 'camera/image_raw'})
    assert {b: e.name for b, e in chosen.items()} == {
        '/odom': 'odom',
        '/zed/left/image': 'camera/image_raw',
    }
    with pytest.raises(ValueError, match='not a topic of the bag'):
        input_topics(bag_topics, {'/nope': 'odom'})
    with pytest.raises(ValueError, match='not an input'):
        input_topics(bag_topics, {'/odom': 'stockpile/keyframes'})
    with pytest.raises(ValueError, match='takes nav_msgs/msg/Odometry'):
        input_topics(bag_topics, {'/zed/left/image': 'odom'})
    both = {'/a': 'nav_msgs/msg/Odometry', '/odom': 'nav_msgs/msg/Odometry'}
    with pytest.raises(ValueError, match='both be published on odom'):
        input_topics(both, {'/a': 'odom'})


def test_parse_mapping() -> None:
    assert parse_mapping('/zed/image=camera/image_raw') == ('/zed/image', 'camera/image_raw')
    for bad in ('/zed/image', '=odom', '/a='):
        with pytest.raises(argparse.ArgumentTypeError):
            parse_mapping(bad)


def test_wait_until_polls_until_true_or_the_deadline() -> None:
    calls = iter([False, False, True])
    assert wait_until(lambda: next(calls), 5.0, period=0.001)
    began = time.monotonic()
    assert not wait_until(lambda: False, 0.1, period=0.01)
    assert 0.09 <= time.monotonic() - began < 1.0
