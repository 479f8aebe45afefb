"""What every node shares: the rclpy message factory, parameters, QoS and topics from the tables."""

from __future__ import annotations

import array
import threading
import traceback
from collections import deque
from collections.abc import Callable
from typing import Any

import rclpy
from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    SetParametersResult,
)
from rclpy.callback_groups import CallbackGroup
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.publisher import Publisher
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.utilities import try_shutdown

from ..errors import StockpileError
from ..ros import topics
from ..ros.publications import Publication
from ..settings import Setting, Settings, build_settings, settings_for
from .interfaces import get_message

__all__ = [
    'Inbox',
    'Publishers',
    'RclpyFactory',
    'SingleRun',
    'current_settings',
    'declare_settings',
    'now_ns',
    'qos_profile',
    'spin',
    'subscribe',
]


def qos_profile(qos: topics.Qos) -> QoSProfile:
    """Return the rclpy profile of a QoS class of the topic table (see :data:`topics.Qos`)."""
    depth = topics.QOS_DEPTH[qos]
    history = HistoryPolicy.KEEP_ALL if depth == 0 else HistoryPolicy.KEEP_LAST
    best_effort = qos in ('sensor', 'pose')
    reliability = ReliabilityPolicy.BEST_EFFORT if best_effort else ReliabilityPolicy.RELIABLE
    durable = qos in ('stream', 'latched', 'status', 'tf_static')
    durability = DurabilityPolicy.TRANSIENT_LOCAL if durable else DurabilityPolicy.VOLATILE
    return QoSProfile(history=history, depth=max(depth, 1), reliability=reliability,
                      durability=durability)  # fmt: skip


class SingleRun:
    """One run at a time in a background thread, so that the node's callbacks return at once."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None

    @property
    def busy(self) -> bool:
        """Whether a run is going on."""
        with self._lock:
            return self._thread is not None and self._thread.is_alive()

    def start(self, target: Callable[..., None], *args: Any) -> bool:
        """Start ``target(*args)`` unless a run is still going on; return whether it started."""
        with self._lock:
            if self._thread is not None and self._thread.is_alive():
                return False
            self._thread = threading.Thread(target=target, args=args, daemon=True)
            self._thread.start()
            return True

    def join(self, timeout_s: float | None = None) -> bool:
        """Wait for the run in progress; return whether none is left."""
        with self._lock:
            thread = self._thread
        if thread is not None:
            thread.join(timeout_s)
        return thread is None or not thread.is_alive()


class Inbox:
    """Work in arrival order, done one item at a time by a thread of its own.

    The subscriptions' callbacks only queue, so the executor takes every topic at the rate it
    comes: rclpy takes one message per subscription per wait, and while image callbacks decoded
    and selected, 30 Hz odometry fell seconds behind 10 Hz images at the start of a pass (its
    keyframes went out without a pose). Queued in arrival order, the component sees the topics
    interleaved as they were published, as a replay does from the bag.

    Args:
        max_droppable: Droppable items (camera frames) kept waiting; the oldest one goes when
            another comes, as a full subscription queue would drop it.
        logger: Where an item that raised is reported (the thread goes on with the next).

    """

    def __init__(self, max_droppable: int, logger: Any) -> None:
        self.max_droppable = max_droppable
        self._logger = logger
        self.dropped = 0
        self._items: deque[tuple[Callable[[], None], bool]] = deque()
        self._droppable = 0
        self._cond = threading.Condition()
        self._busy = False
        self._open = True
        self._thread = threading.Thread(target=self._work, daemon=True)
        self._thread.start()

    def put(self, work: Callable[[], None], droppable: bool = False) -> None:
        """Queue ``work``; a droppable item beyond ``max_droppable`` drops the oldest one."""
        with self._cond:
            self._items.append((work, droppable))
            self._droppable += droppable
            if self._droppable > self.max_droppable:
                oldest = next(i for i, (_, d) in enumerate(self._items) if d)
                del self._items[oldest]
                self._droppable -= 1
                self.dropped += 1
            self._cond.notify_all()

    def drain(self, timeout_s: float) -> bool:
        """Wait until everything queued has been done; return whether it has."""
        with self._cond:
            return self._cond.wait_for(lambda: not self._items and not self._busy, timeout_s)

    def close(self, timeout_s: float = 10.0) -> None:
        """Do what is queued, then stop the thread."""
        with self._cond:
            self._open = False
            self._cond.notify_all()
        self._thread.join(timeout_s)

    def _work(self) -> None:
        while True:
            with self._cond:
                self._cond.wait_for(lambda: self._items or not self._open)
                if not self._items:
                    return
                work, droppable = self._items.popleft()
                self._droppable -= droppable
                self._busy = True
            try:
                work()
            except Exception:  # one bad message must not stop the node
                self._logger.error(traceback.format_exc())
            finally:
                with self._cond:
                    self._busy = False
                    self._cond.notify_all()


class RclpyFactory:
    """Message factory over the rclpy message packages (see stockpile_ros.ros.messages)."""

    def cls(self, msgtype: str) -> Any:
        """Return the rclpy class of ``pkg/msg/Name``."""
        return get_message(msgtype)

    def u8(self, data: Any) -> Any:
        """Return ``array('B')``: the ``uint8[]`` setter takes it as is, a list would be checked."""
        out = array.array('B')
        out.frombytes(memoryview(data).cast('B'))
        return out

    def f64(self, data: Any) -> Any:
        """Return ``array('d')`` (rclpy takes it for fixed and unbounded ``float64[]``)."""
        return _array('d', 'f8', data)

    def u32(self, data: Any) -> Any:
        """Return ``array('I')`` for ``uint32[]``."""
        return _array('I', 'u4', data)


def _array(code: str, dtype: str, data: Any) -> array.array[Any]:
    if hasattr(data, 'astype'):
        # numpy: one copy through the buffer, not a Python object per element.
        out = array.array(code)
        out.frombytes(data.astype(dtype).reshape(-1).tobytes())
        return out
    return array.array(code, data)


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
    """Declare the parameters of ``component`` (settings table); refuse bad values when set.

    Every change is checked as the command line checks it (type, finiteness, range, choices,
    a target spec that parses) before it is accepted, so a worker never starts with it.
    """
    for setting in settings_for(component):
        node.declare_parameter(setting.name, setting.default, _descriptor(setting))

    def check(params: list[Parameter]) -> SetParametersResult:
        changed = {p.name: p.value for p in params}
        try:
            _build(node, component, changed)
        except StockpileError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    node.add_on_set_parameters_callback(check)


def _build(node: Node, component: str, changed: dict[str, Any]) -> Settings:
    """Build the settings from the node's values with ``changed`` applied.

    A node cannot tell a value its parameter file gave from a default, so the values that differ
    from the table's count as set explicitly (they beat the ``segment.mode`` preset), and so do
    the ones just being set.
    """
    table = settings_for(component)
    values = {s.name: node.get_parameter(s.name).value for s in table}
    values.update({k: v for k, v in changed.items() if k in values})
    explicit = {s.name for s in table if values[s.name] != s.default} | changed.keys() & values
    return build_settings(values, explicit=explicit)


def current_settings(node: Node, component: str) -> Settings:
    """Build the option objects from the node's current parameter values."""
    return _build(node, component, {})


def now_ns(node: Node) -> int:
    """Return the node's clock (simulated time under ``use_sim_time``) in nanoseconds."""
    stamp: int = node.get_clock().now().nanoseconds
    return stamp


def subscribe(
    node: Node,
    name: str,
    callback: Callable[[Any], None],
    group: CallbackGroup | None = None,
) -> None:
    """Subscribe to a topic of the table with its type and QoS."""
    entry = topics.topic(name)
    node.create_subscription(get_message(entry.msgtype), entry.name, callback,
                             qos_profile(entry.qos), callback_group=group)  # fmt: skip


class Publishers:
    """The publishers of a component's topics (topic table), fed with ``(topic, message)`` pairs.

    Warnings and errors among the diagnostics are logged too, so the console says what the
    dashboards show.

    Args:
        node: The node that owns them.
        component: The component whose topics these are.

    """

    def __init__(self, node: Node, component: str) -> None:
        self._logger = node.get_logger()
        self._pubs: dict[str, Publisher] = {
            entry.name: node.create_publisher(
                get_message(entry.msgtype), entry.name, qos_profile(entry.qos)
            )
            for entry in topics.published_by(component)
        }

    def publish(self, publications: list[Publication]) -> None:
        """Publish each message on its topic."""
        for name, msg in publications:
            self._pubs[name].publish(msg)
            if name == topics.DIAGNOSTICS:
                self._log([s for s in msg.status if s.level != msg.status[0].OK])

    def _log(self, statuses: list[Any]) -> None:
        text = '; '.join(f'{s.name}: {s.message}' for s in statuses)
        if text:
            self._logger.warning(text)


def spin(*node_types: Callable[[], Node], args: list[str] | None = None) -> None:
    """Run nodes in one process on a multi-threaded executor until shut down.

    Multi-threaded so that a service or a trigger is answered while a worker runs a stage. On
    shutdown each node's ``close()`` (when it has one) waits for its worker.
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
            getattr(node, 'close', lambda: None)()
            node.destroy_node()
        try_shutdown()
