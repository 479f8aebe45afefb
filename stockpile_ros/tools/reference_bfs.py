"""The paper's search as written: a per-face breadth-first search with restarts, in plain Python.

Kept only as the reference the vectorised :func:`stockpile_ros.segment.region.grow_regions` is
tested
and benchmarked against; it is some 10-20 times slower.
"""

from __future__ import annotations

from collections import deque

import numpy as np
import numpy.typing as npt

from ..segment.adjacency import FaceAdjacency
from ..segment.criterion import edge_score

__all__ = ['reference_bfs']


def reference_bfs(
    centroids: npt.NDArray[np.float64],
    normals: npt.NDArray[np.float64],
    adjacency: FaceAdjacency,
    threshold: float,
    seeds: npt.NDArray[np.int64],
) -> npt.NDArray[np.int32]:
    """Breadth-first search per seed, Eq. 2 tested from the current face to each new neighbour.

    A neighbour that fails is marked as boundary for this run and stays unvisited, so a later run
    can
    start from it or reach it.

    Args:
        centroids: Mx3 face centroids.
        normals: Mx3 unit face normals used in Eq. 2.
        adjacency: Face pairs the search may cross.
        threshold: ``t`` of Eq. 2.
        seeds: Restart order; faces left out are never seeds.

    Returns:
        Labels 1..K in seed order, 0 for faces never reached.

    """
    m = len(centroids)
    src, dst = adjacency.src, adjacency.dst
    by_src = np.argsort(src, kind='stable')
    start = np.searchsorted(src[by_src], np.arange(m + 1)).tolist()
    neighbours = dst[by_src].tolist()
    c = [tuple(p) for p in centroids.tolist()]
    n = [tuple(p) for p in normals.tolist()]
    labels = [0] * m
    current = 0
    for seed in seeds.tolist():
        if labels[seed]:
            continue
        current += 1
        labels[seed] = current
        queue = deque([seed])
        while queue:
            i = queue.popleft()
            ci, ni = c[i], n[i]
            for k in range(start[i], start[i + 1]):
                j = neighbours[k]
                if labels[j] == 0 and edge_score(ci, c[j], ni, n[j]) > threshold:
                    labels[j] = current
                    queue.append(j)
    return np.asarray(labels, dtype=np.int32)
