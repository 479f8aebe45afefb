"""The curvature criterion of the paper's Eq. 2, evaluated on every directed edge at once.

``(c + n_j) . n_i > t``: ``i`` is the face the search stands on, ``j`` its neighbour, ``n`` unit
face
normals and ``c`` the unit vector between the two centroids. ``c`` points from the neighbour back to
the current face, ``c = (centroid_i - centroid_j) / |centroid_i - centroid_j|``: across a convex
ridge
``c . n_i > 0`` and the sum stays near 1, in a concave valley ``c . n_i < 0`` and the sum drops
below
``t`` once the crease is sharp, which is the paper's stated intent (growth stops at the concave
creases where rocks meet). The test is not symmetric in ``i`` and ``j``.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from .blocks import blocks

__all__ = ['PAPER_THRESHOLD', 'edge_score', 'edge_scores']

#: The threshold printed in the paper (section 3.2, "about 45 degrees"); the authors' code used
# 0.81.
PAPER_THRESHOLD = 0.7

F64 = npt.NDArray[np.float64]


def edge_scores(
    centroids: F64, normals: F64, i: npt.NDArray[np.int64], j: npt.NDArray[np.int64]
) -> tuple[F64, F64]:
    """Left-hand side of Eq. 2 on every face pair, in both directions.

    Written as ``c . n_cur + n_nb . n_cur`` (equal to Eq. 2 by distributivity); reversing the pair
    negates ``c`` exactly in floating point, so one pass over the pairs gives both directions
    bit-identical to :func:`edge_score`, which the per-face reference uses.

    Returns:
        Scores with ``i`` as the current face (towards ``j``), and with ``j`` as the current face.

    """
    # Gathered a coordinate at a time from contiguous columns: a third faster than gathering
    # rows, and the values are the same.
    c, n = np.ascontiguousarray(centroids.T), np.ascontiguousarray(normals.T)
    towards_j, towards_i = np.empty(len(i)), np.empty(len(i))
    for at in blocks(len(i)):
        a, b = i[at], j[at]
        dx = c[0].take(a) - c[0].take(b)
        dy = c[1].take(a) - c[1].take(b)
        dz = c[2].take(a) - c[2].take(b)
        norm = np.sqrt(dx * dx + dy * dy + dz * dz)
        safe = np.where(norm > 0, norm, 1.0)
        cx, cy, cz = dx / safe, dy / safe, dz / safe
        nix, niy, niz = n[0].take(a), n[1].take(a), n[2].take(a)
        njx, njy, njz = n[0].take(b), n[1].take(b), n[2].take(b)
        nn = njx * nix + njy * niy + njz * niz
        towards_j[at] = (cx * nix + cy * niy + cz * niz) + nn
        towards_i[at] = -(cx * njx + cy * njy + cz * njz) + nn
    return towards_j, towards_i


def edge_score(
    ci: tuple[float, float, float],
    cj: tuple[float, float, float],
    ni: tuple[float, float, float],
    nj: tuple[float, float, float],
) -> float:
    """Left-hand side of Eq. 2 for current face ``i`` and neighbour ``j``, in plain floats."""
    dx = ci[0] - cj[0]
    dy = ci[1] - cj[1]
    dz = ci[2] - cj[2]
    norm = math.sqrt(dx * dx + dy * dy + dz * dz)
    if norm == 0:
        norm = 1.0
    cx, cy, cz = dx / norm, dy / norm, dz / norm
    nn = nj[0] * ni[0] + nj[1] * ni[1] + nj[2] * ni[2]
    return (cx * ni[0] + cy * ni[1] + cz * ni[2]) + nn
