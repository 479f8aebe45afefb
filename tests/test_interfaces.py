"""Interface classes by name (stockpile_ros.nodes.interfaces), with and without ROS installed."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

from stockpile_ros.nodes.interfaces import get_message, get_service

PACKAGE = 'stockpile_test_fake_interfaces'


@pytest.fixture
def fake_package(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> str:
    """A package laid out as rosidl_generator_py lays one out: ``pkg/msg`` and ``pkg/srv``."""
    root = tmp_path / PACKAGE
    for kind, cls in (('msg', 'Thing'), ('srv', 'DoIt')):
        (root / kind).mkdir(parents=True)
        (root / kind / '__init__.py').write_text(f'class {cls}:\n    kind = {kind!r}\n')
    (root / '__init__.py').write_text('')
    monkeypatch.syspath_prepend(str(tmp_path))
    for name in (PACKAGE, f'{PACKAGE}.msg', f'{PACKAGE}.srv'):
        monkeypatch.delitem(sys.modules, name, raising=False)
    return PACKAGE


def test_names_resolve_to_the_generated_classes(fake_package: str) -> None:
    thing = get_message(f'{fake_package}/msg/Thing')
    assert thing.__name__ == 'Thing' and thing.kind == 'msg'
    assert thing.__module__ == f'{fake_package}.msg'
    service = get_service(f'{fake_package}/srv/DoIt')
    assert service.__name__ == 'DoIt' and service.kind == 'srv'


@pytest.mark.parametrize(
    'name', ['Thing', 'pkg/Thing', 'pkg/msg/Thing/x', 'pkg/srv/Thing', '/msg/Thing', 'pkg/msg/']
)
def test_malformed_message_names_are_refused(name: str) -> None:
    with pytest.raises(ValueError, match='pkg/msg/Name'):
        get_message(name)


def test_a_message_name_is_not_a_service_name(fake_package: str) -> None:
    with pytest.raises(ValueError, match='pkg/srv/Name'):
        get_service(f'{fake_package}/msg/Thing')


def test_missing_package_and_missing_type_say_which(fake_package: str) -> None:
    with pytest.raises(ModuleNotFoundError):
        get_message('stockpile_no_such_package/msg/Thing')
    with pytest.raises(ImportError, match="'Nope'"):
        get_message(f'{fake_package}/msg/Nope')


@pytest.mark.skipif(
    importlib.util.find_spec('std_msgs') is None, reason='no ROS message packages installed'
)
def test_real_ros_messages_and_services() -> None:
    from std_msgs.msg import String
    from std_srvs.srv import Trigger

    assert get_message('std_msgs/msg/String') is String
    assert get_service('std_srvs/srv/Trigger') is Trigger
    assert get_message('tf2_msgs/msg/TFMessage')().transforms == []
