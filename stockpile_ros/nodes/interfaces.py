"""ROS interface classes by their names, without ``rosidl_runtime_py`` (it is not on PyPI).

rosidl_generator_py puts ``pkg/msg/Name`` in module ``pkg.msg`` as class ``Name`` (``pkg/srv/Name``
in ``pkg.srv``), so importlib finds it: this module imports nothing from ROS itself and works with
the PyPI wheels and a sourced ROS installation alike.
"""

from __future__ import annotations

import importlib
from typing import Any

__all__ = ['get_message', 'get_service']


def _interface(name: str, kind: str) -> Any:
    """Return the class that ``name`` (``pkg/KIND/Name``) names.

    Raises:
        ValueError: ``name`` is not of the form ``pkg/KIND/Name``.
        ModuleNotFoundError: Package ``pkg`` (or its ``KIND`` module) is not installed.
        ImportError: The package has no interface ``Name``.

    """
    parts = name.split('/')
    if len(parts) != 3 or parts[1] != kind or not all(p.isidentifier() for p in parts):
        raise ValueError(f'not a {kind} type name (pkg/{kind}/Name): {name!r}')
    package, _, type_name = parts
    module = importlib.import_module(f'{package}.{kind}')
    try:
        return getattr(module, type_name)
    except AttributeError:
        # The message of ``from pkg.msg import Name``, so the cause reads the same as there.
        raise ImportError(
            f'cannot import name {type_name!r} from {module.__name__!r}', name=module.__name__
        ) from None


def get_message(name: str) -> Any:
    """Return the message class of ``pkg/msg/Name`` (``std_msgs/msg/String``, say).

    Raises:
        ValueError: ``name`` is not of the form ``pkg/msg/Name``.
        ModuleNotFoundError: Package ``pkg`` is not installed.
        ImportError: The package has no message ``Name``.

    """
    return _interface(name, 'msg')


def get_service(name: str) -> Any:
    """Return the service class of ``pkg/srv/Name`` (``std_srvs/srv/Trigger``, say).

    Raises:
        ValueError: ``name`` is not of the form ``pkg/srv/Name``.
        ModuleNotFoundError: Package ``pkg`` is not installed.
        ImportError: The package has no service ``Name``.

    """
    return _interface(name, 'srv')
