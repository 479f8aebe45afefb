"""Our message types (``msg_schemas/msg/*.msg``) registered with the rosbags typestore.

The same ``.msg`` files build the ``stockpile_msgs`` interface package on the cart; here they are
parsed by rosbags so that bags holding our types can be written and read without ROS.
"""

from __future__ import annotations

import os
import sys
from functools import cache
from pathlib import Path

from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

__all__ = ['MSG_PACKAGE', 'find_msg_dir', 'register_types', 'typestore']

MSG_PACKAGE = 'stockpile_msgs'


def _candidate_dirs() -> list[Path]:
    dirs: list[Path] = []
    if env := os.environ.get('STOCKPILE_MSG_DIR'):
        dirs.append(Path(env))
    # A colcon-built stockpile_msgs, found through the ament prefixes.
    for prefix in filter(None, os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep)):
        dirs.append(Path(prefix) / 'share' / MSG_PACKAGE / 'msg')
    # The source tree (editable installs, tests).
    dirs.append(Path(__file__).resolve().parents[2] / 'msg_schemas' / 'msg')
    # Installed beside this package through setup.py's data_files (pip or colcon).
    dirs.append(Path(sys.prefix) / 'share' / 'stockpile_ros' / 'msg_schemas' / 'msg')
    return dirs


def find_msg_dir() -> Path:
    """Return the folder that holds our ``.msg`` files.

    Looks, in order, at ``$STOCKPILE_MSG_DIR``, ``share/stockpile_msgs/msg`` under each
    ``$AMENT_PREFIX_PATH`` entry, the source tree, and the pip/colcon data files.

    Raises:
        FileNotFoundError: No candidate folder holds ``Rock.msg``.

    """
    candidates = _candidate_dirs()
    for path in candidates:
        if (path / 'Rock.msg').is_file():
            return path
    searched = ', '.join(str(p) for p in candidates)
    raise FileNotFoundError(f'stockpile_msgs .msg files not found; searched {searched}')


def register_types(store: Typestore, msg_dir: Path | None = None) -> None:
    """Register every ``.msg`` of ``stockpile_msgs`` with a rosbags typestore.

    Args:
        store: The typestore to extend.
        msg_dir: Folder of ``.msg`` files; found with :func:`find_msg_dir` when None.

    """
    folder = msg_dir or find_msg_dir()
    types = {}
    for path in sorted(folder.glob('*.msg')):
        types.update(get_types_from_msg(path.read_text(), f'{MSG_PACKAGE}/msg/{path.stem}'))
    store.register(types)


@cache
def typestore() -> Typestore:
    """Return the ROS 2 Jazzy typestore with our types registered (built once)."""
    store = get_typestore(Stores.ROS2_JAZZY)
    register_types(store)
    return store
