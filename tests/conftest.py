"""Session-wide set-up: keep DDS traffic of the rclpy tests on this host, in a domain of its own.

Set at import time, which pytest does before it collects (and so imports) any test module: rcl
reads both variables when rclpy.init() creates a context, so they must be in place before then.
Several agents and CI runs share a machine: a domain id per process keeps their nodes from finding
each other, and the localhost range keeps every participant off the network.
"""

from __future__ import annotations

import os
from collections.abc import Iterator

import pytest

# Overwritten, not defaulted: a developer's own ROS_DOMAIN_ID would put the test nodes on the
# domain of the robot or the tools they are running.
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
# 1..101: 0 is everyone's default, and above 101 the DDS ports reach Linux's ephemeral port range.
os.environ['ROS_DOMAIN_ID'] = str(1 + os.getpid() % 101)


@pytest.fixture
def ros() -> Iterator[None]:
    """An rclpy context for one test (the test module skips itself where rclpy is missing)."""
    import rclpy

    rclpy.init()
    try:
        yield
    finally:
        rclpy.try_shutdown()
