"""Errors that carry a message meant for the user, never a bare traceback."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

__all__ = ['BagError', 'CaptureError', 'MeshError', 'StockpileError', 'reading']


class StockpileError(Exception):
    """Base of every error the command line reports as a message rather than a traceback."""


class BagError(StockpileError):
    """A bag, or one message in it, that cannot be used.

    Args:
        bag: Path of the bag.
        what: What is wrong, in words.
        topic: Topic of the offending message, if any.
        index: Index of the message within its topic (0-based), if any.

    """

    def __init__(self, bag: str, what: str, topic: str | None = None, index: int | None = None):
        self.bag = bag
        self.what = what
        self.topic = topic
        self.index = index
        where = bag
        if topic is not None:
            where += f', topic {topic}'
        if index is not None:
            where += f', message {index}'
        super().__init__(f'{where}: {what}')


class CaptureError(StockpileError):
    """The capture was not good enough for a stage to succeed.

    Args:
        stage: The stage that failed, e.g. ``"sfm"``.
        reason: What went wrong, measured.
        advice: What the operator should do about it.

    """

    def __init__(self, stage: str, reason: str, advice: str):
        self.stage = stage
        self.reason = reason
        self.advice = advice
        super().__init__(f'{stage}: {reason}. {advice}')


class MeshError(StockpileError, ValueError):
    """A mesh file or mesh that cannot be used; the text names the file and the fault.

    A ``ValueError`` too, so that callers written against the older reader keep catching it.
    """


@contextmanager
def reading(path: Path, kind: str) -> Iterator[None]:
    """Turn the operating system's errors while reading ``path`` into a :class:`MeshError`.

    Args:
        path: The file being read.
        kind: What it should be, in words (``mesh file``, ``point cloud file``).

    """
    try:
        yield
    except FileNotFoundError:
        raise MeshError(f'{path}: no such {kind}') from None
    except IsADirectoryError:
        raise MeshError(f'{path}: a folder, not a {kind}') from None
    except OSError as exc:
        raise MeshError(f'{path}: cannot read ({exc.strerror or exc})') from None
