"""Element-wise work over a million faces or edges, a block at a time.

A chain of numpy operations over whole arrays of a million elements writes every temporary to
main memory and reads it back; over blocks of a few thousand the temporaries stay in the
processor's cache. The values are the same (each element's operations are unchanged); on the
1.08 M-face pile of bench/bench_segment.py the face geometry and the scores of Eq. 2 take about
half their time.
"""

from __future__ import annotations

from collections.abc import Iterator

__all__ = ['BLOCK', 'blocks']

#: Elements per block: a block's dozen float64 temporaries fit a core's L2 cache.
BLOCK = 16384


def blocks(n: int) -> Iterator[slice]:
    """Yield slices that cover ``range(n)`` in order, ``BLOCK`` elements each (the last fewer)."""
    for start in range(0, n, BLOCK):
        yield slice(start, min(start + BLOCK, n))
