"""Meshes shared by the segmentation tests: a small synthetic pile and height fields."""

from __future__ import annotations

import functools
from collections.abc import Callable

import numpy as np
import numpy.typing as npt

from stockpile_ros.tools.synthetic import make_pile, poisson_mesh


@functools.lru_cache(maxsize=1)
def small_pile() -> tuple[npt.NDArray[np.float64], npt.NDArray[np.int64], object]:
    pile = make_pile(4, seed=3, size=(0.15, 0.22), spread=0.2, density=20000, candidates=3)
    v, f = poisson_mesh(pile.points, pile.normals, depth=7)
    return v, f, pile


def height_field(
    z: Callable[[npt.NDArray[np.float64], npt.NDArray[np.float64]], npt.NDArray[np.float64]],
    half: float,
    n: int,
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.int64]]:
    """Triangulated ``z(x, y)`` on an ``n`` x ``n`` grid over ``[-half, half]^2``, normals up."""
    x, y = np.meshgrid(np.linspace(-half, half, n), np.linspace(-half, half, n), indexing='ij')
    v = np.stack([x.ravel(), y.ravel(), z(x, y).ravel()], axis=1)
    k = np.arange(n * n).reshape(n, n)
    a, b, c, d = k[:-1, :-1].ravel(), k[1:, :-1].ravel(), k[1:, 1:].ravel(), k[:-1, 1:].ravel()
    f = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return v, f
