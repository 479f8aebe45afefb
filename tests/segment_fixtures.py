"""Small synthetic pile shared by the segmentation tests (built once per session)."""

from __future__ import annotations

import functools

import numpy as np
import numpy.typing as npt

from stockpile_ros.segment.synthetic import make_pile, poisson_mesh


@functools.lru_cache(maxsize=1)
def small_pile() -> tuple[npt.NDArray[np.float64], npt.NDArray[np.int64], object]:
    pile = make_pile(4, seed=3, size=(0.15, 0.22), spread=0.2, density=20000, candidates=3)
    v, f = poisson_mesh(pile.points, pile.normals, depth=7)
    return v, f, pile
