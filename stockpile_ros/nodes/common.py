"""What every node shares: the rclpy message factory, parameters from the settings table, QoS."""

from __future__ import annotations

import array
import threading
from collections.abc import Callable
from typing import Any

import rclpy
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from ..publish import Publication
from ..settings import Setting, Settings, build_settings, settings_for
from .interfaces import get_message

__all__ = [
    'LATCHED',
    'Publishers',
    'RclpyFactory',
    'SingleRun',
    'current_settings',
    'declare_settings',
    'now_ns',
    'spin',
]

LATCHED = QoSProfile(
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
    history=HistoryPolicy.KEEP_LAST,
)
"""Results: a dashboard that connects late still gets the last one (subscribe the same way)."""


class SingleRun:
    """One run at a time in a background thread, so that the node's callbacks return at once."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None

    def start(self, target: Callable[..., None], *args: Any) -> bool:
        """Start ``target(*args)`` unless a run is still going on; return whether it started."""
        with self._lock:
            if self._thread is not None and self._thread.is_alive():
                return False
            self._thread = threading.Thread(target=target, args=args, daemon=True)
            self._thread.start()
            return True


class RclpyFactory:
    """Message factory over the rclpy message packages (see stockpile_ros.messages)."""

    def cls(self, msgtype: str) -> Any:
        """Return the rclpy class of ``pkg/msg/Name``."""
        return get_message(msgtype)

    def u8(self, data: Any) -> Any:
        """Return ``array('B')``: the ``uint8[]`` setter takes it as is, a list would be checked."""
        out = array.array('B')
        out.frombytes(memoryview(data).cast('B'))
        return out

    def f64(self, data: Any) -> Any:
        """Return a list of floats (rclpy accepts it for fixed and unbounded ``float64[]``)."""
        flat = data.reshape(-1).tolist() if hasattr(data, 'reshape') else list(data)
        return [float(v) for v in flat]


def _descriptor(setting: Setting) -> ParameterDescriptor:
    # No name or type: declare_parameter sets both itself (from the name and the default's type).
    descriptor = ParameterDescriptor(description=setting.description, read_only=setting.read_only)
    if setting.choices:
        descriptor.additional_constraints = 'one of: ' + ', '.join(setting.choices)
    if setting.low is not None and setting.high is not None:
        if isinstance(setting.default, float):
            descriptor.floating_point_range = [
                FloatingPointRange(
                    from_value=float(setting.low), to_value=float(setting.high), step=0.0
                )
            ]
        else:
            descriptor.integer_range = [
                IntegerRange(from_value=int(setting.low), to_value=int(setting.high), step=1)
            ]
    return descriptor  # fmt: skip


def declare_settings(node: Node, component: str) -> None:
    """Declare the parameters of ``component`` (settings table) with descriptors and ranges."""
    for setting in settings_for(component):
        node.declare_parameter(setting.name, setting.default, _descriptor(setting))


def current_settings(node: Node, component: str) -> Settings:
    """Build the option objects from the node's current parameter values."""
    return build_settings(
        {s.name: node.get_parameter(s.name).value for s in settings_for(component)}
    )


def now_ns(node: Node) -> int:
    """Return the node's clock (simulated time under ``use_sim_time``) in nanoseconds."""
    stamp: int = node.get_clock().now().nanoseconds
    return stamp


class Publishers:
    """Latched publishers by topic, created up front, fed with ``(topic, message)`` pairs.

    Args:
        node: The node that owns them.
        types: Message type (``pkg/msg/Name``) by relative topic name.

    """

    def __init__(self, node: Node, types: dict[str, str]) -> None:
        self._pubs: dict[str, Publisher] = {
            topic: node.create_publisher(get_message(msgtype), topic, LATCHED)
            for topic, msgtype in types.items()
        }

    def publish(self, publications: list[Publication]) -> None:
        """Publish each message on its topic."""
        for topic, msg in publications:
            self._pubs[topic].publish(msg)


def spin(*node_types: type[Node], args: list[str] | None = None) -> None:
    """Run nodes in one process on a multi-threaded executor until shut down.

    Multi-threaded so that a service or a trigger is answered while a worker runs a stage.
    """
    rclpy.init(args=args)
    nodes: list[Node] = []
    executor = MultiThreadedExecutor()
    try:
        nodes = [node_type() for node_type in node_types]
        for node in nodes:
            executor.add_node(node)
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        executor.shutdown()
        for node in nodes:
            node.destroy_node()
        rclpy.try_shutdown()
