"""ROS 2 Jazzy as scripts/setup.sh installs it: required in CI where its wheels exist.

Elsewhere (another OS, architecture or Python) the rclpy tests skip; in CI on a platform with
wheels, a missing package means the set-up broke, so the run fails here instead of going green
with the node layer never exercised.
"""

from __future__ import annotations

import importlib
import os
import platform
import sys
from pathlib import Path
from typing import Any

import pytest

# The platforms the Jazzy wheels exist for (see scripts/setup_ros.sh).
WHEELS_EXIST = (
    sys.platform == 'linux'
    and platform.machine() == 'x86_64'
    and (3, 10) <= sys.version_info[:2] <= (3, 12)
)
REQUIRED = os.environ.get('CI') == 'true' and WHEELS_EXIST

# tf2_msgs/msg/TFMessage's type hash in upstream ROS 2 Jazzy (`ros2 topic info -v /tf` there): ours
# must match, or a real tf2 publisher's /tf and our subscriber disagree on the type.
UPSTREAM_TFMESSAGE_HASH = 'RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087'


def _import_or_skip(module: str) -> Any:
    try:
        return importlib.import_module(module)
    except ImportError as exc:
        if REQUIRED:
            pytest.fail(f'CI on a platform with ROS 2 Jazzy wheels, but {module}: {exc}')
        pytest.skip(f'{module} is not installed ({exc}); scripts/setup.sh installs it')


@pytest.mark.parametrize(
    'module',
    [
        'rclpy',
        'rclpy.executors',
        'rmw_fastrtps_cpp',
        'std_srvs.srv',
        'nav_msgs.msg',
        'sensor_msgs.msg',
        'diagnostic_msgs.msg',
        'visualization_msgs.msg',
        'stockpile_msgs.msg',
        'tf2_msgs.msg',
    ],
)
def test_ros_package_imports(module: str) -> None:
    _import_or_skip(module)


def test_dds_stays_on_this_host_in_a_domain_of_its_own() -> None:
    # Set by conftest.py before any test module imported rclpy.
    assert os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] == 'LOCALHOST'
    assert 1 <= int(os.environ['ROS_DOMAIN_ID']) <= 101
    rclpy = _import_or_skip('rclpy')
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        assert context.get_domain_id() == int(os.environ['ROS_DOMAIN_ID'])
    finally:
        rclpy.shutdown(context=context)


def test_every_message_file_was_built() -> None:
    msg = _import_or_skip('stockpile_msgs.msg')
    sources = Path(__file__).resolve().parent.parent / 'msg_schemas' / 'msg'
    names = sorted(p.stem for p in sources.glob('*.msg'))
    assert names, sources
    missing = [n for n in names if not hasattr(msg, n)]
    assert not missing, f'stale stockpile_msgs build, rerun scripts/setup.sh: {missing}'


def test_tf2_msgs_type_hash_equals_upstream_jazzy() -> None:
    # The hash the middleware announces for a TFMessage publisher, which is what a peer compares.
    tf2_msgs = _import_or_skip('tf2_msgs.msg')
    rclpy = _import_or_skip('rclpy')
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        node = rclpy.create_node('stockpile_type_hash_probe', context=context)
        node.create_publisher(tf2_msgs.TFMessage, 'type_hash_probe', 1)
        (info,) = node.get_publishers_info_by_topic('type_hash_probe')
        assert str(info.topic_type_hash) == UPSTREAM_TFMESSAGE_HASH
        node.destroy_node()
    finally:
        rclpy.shutdown(context=context)


def test_a_missing_package_fails_in_ci_and_skips_elsewhere(monkeypatch: pytest.MonkeyPatch) -> None:
    module = sys.modules[__name__]
    monkeypatch.setattr(module, 'REQUIRED', True)
    with pytest.raises(pytest.fail.Exception, match='stockpile_no_such_ros_package'):
        _import_or_skip('stockpile_no_such_ros_package.msg')
    monkeypatch.setattr(module, 'REQUIRED', False)
    with pytest.raises(pytest.skip.Exception, match=r'scripts/setup\.sh'):
        _import_or_skip('stockpile_no_such_ros_package.msg')
