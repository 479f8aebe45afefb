"""A live ROS 2 graph for tests and benchmarks: a recorder of every output, a player, the rig.

Imported by tests/test_nodes_live.py and bench/bench_live.py (rclpy must be importable).
"""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from rclpy.qos import HistoryPolicy
from std_srvs.srv import Trigger

from stockpile_ros.nodes.common import qos_profile
from stockpile_ros.nodes.interfaces import get_message
from stockpile_ros.ros import topics

DONE, FAILED = 4, 5
OUTPUTS = [t for t in topics.TABLE if t.publishers]


class Recorder(Node):
    """Every output topic of the node set, subscribed as the table says, in arrival order."""

    def __init__(self, name: str = 'stockpile_test_recorder') -> None:
        super().__init__(name)
        self.lock = threading.Lock()
        self.got: list[tuple[str, Any, float]] = []  # topic, message, time.monotonic()
        for entry in OUTPUTS:
            # Reliability and durability as the table says, but a deep history: with the table's
            # depth of 1 for latched topics, two samples in quick succession on a loaded machine
            # left only the second one.
            profile = qos_profile(entry.qos)
            if profile.history == HistoryPolicy.KEEP_LAST:
                profile.depth = max(profile.depth, 100)
            self.create_subscription(get_message(entry.msgtype), entry.name,
                                     self._keep(entry.name), profile)  # fmt: skip

    def _keep(self, name: str) -> Any:
        def callback(msg: Any) -> None:
            with self.lock:
                self.got.append((name, msg, time.monotonic()))

        return callback

    def on(self, name: str) -> list[Any]:
        with self.lock:
            return [msg for n, msg, _ in self.got if n == name]

    def times(self, name: str) -> list[float]:
        with self.lock:
            return [t for n, _, t in self.got if n == name]

    def finished(self) -> bool:
        return any(s.state in (DONE, FAILED) for s in self.on(topics.STATUS))


def spin(*nodes: Node) -> tuple[MultiThreadedExecutor, threading.Thread]:
    executor = MultiThreadedExecutor()
    for node in nodes:
        executor.add_node(node)
    thread = threading.Thread(target=executor.spin, daemon=True)
    thread.start()
    return executor, thread


def play(bag: Path, rate: float = 1.0) -> None:
    """Publish the bag's inputs at real rate from another process, and wait for it to end."""
    done = subprocess.run([sys.executable, '-m', 'stockpile_ros.nodes.player', str(bag),
                           '--rate', str(rate)], capture_output=True, text=True, timeout=120,
                          env=os.environ.copy())  # fmt: skip
    assert done.returncode == 0, done.stderr


def trigger(node: Node) -> Any:
    client = node.create_client(Trigger, topics.RECONSTRUCT_SERVICE)
    assert client.wait_for_service(timeout_sec=20)
    future = client.call_async(Trigger.Request())
    deadline = time.monotonic() + 20
    while not future.done() and time.monotonic() < deadline:
        time.sleep(0.02)
    assert future.done(), 'no answer from the reconstruct service'
    return future.result()


def wait(recorder: Recorder, timeout_s: float = 300.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not recorder.finished() and time.monotonic() < deadline:
        time.sleep(0.1)
    assert recorder.finished(), 'no DONE or FAILED status'
    time.sleep(0.5)  # the results published with the last status


def rig(role: str, work: Path, params: dict[str, Any]) -> subprocess.Popen[str]:
    params = [f'work_dir:={work}', *(f'{k}:={v}' for k, v in params.items())]
    args = [sys.executable, '-m', 'stockpile_ros.nodes.rig', '--role', role, '--ros-args']
    args += [word for param in params for word in ('-p', param)]
    return subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            env=os.environ.copy())  # fmt: skip
