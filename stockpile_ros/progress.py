"""One progress bar for every long piece of work (tqdm on stderr, quiet when not a terminal)."""

from __future__ import annotations

import sys
from collections.abc import Iterable, Iterator
from typing import TypeVar

from tqdm import tqdm

__all__ = ['progress']

T = TypeVar('T')


def progress(
    items: Iterable[T], desc: str, total: int | None = None, unit: str = 'it'
) -> Iterator[T]:
    """Iterate over ``items`` with a progress bar on stderr (shown only on a terminal)."""
    yield from tqdm(
        items, desc=desc, total=total, unit=unit, disable=not sys.stderr.isatty(), leave=False
    )
