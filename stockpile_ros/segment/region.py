"""Region growing of the paper's search, vectorised and exact.

The paper's search starts at a seed, adds every unvisited neighbour that passes Eq. 2 from the
face it stands on, and restarts at the next unvisited face until the mesh is covered. The faces
one run collects are the faces reachable from its seed in the directed graph of passing edges,
restricted to faces no earlier run took. The union of earlier runs is closed under that
reachability (a run stops only where no passing edge leads out), so the restriction changes
nothing: a face belongs to the first seed, in seed order, that can reach it.

That is computed here with one compiled depth-first search: virtual nodes ``v_0 -> v_1 -> ...``
chain the seeds, ``v_k`` points first to seed ``k`` and then to ``v_{k+1}``; a depth-first search
from ``v_0`` finishes everything seed ``k`` reaches before it moves on to ``v_{k+1}``, so the run
of a face is the number of virtual nodes before it in the discovery order. The labels equal those
of the per-face search in :mod:`stockpile_ros.tools.reference_bfs` exactly (tested), at compiled
speed.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import scipy.sparse as sp
from scipy.sparse.csgraph import depth_first_order

__all__ = ['grow_regions']

I64 = npt.NDArray[np.int64]


def grow_regions(targets: I64, seeds: I64) -> npt.NDArray[np.int32]:
    """Label faces by the first seed that reaches them over directed passing edges.

    Args:
        targets: M x K: row ``f`` lists the faces Eq. 2 admits from ``f`` (``f`` current), ``f``
            itself in the places of those it does not (see
            :meth:`~stockpile_ros.segment.adjacency.FaceAdjacency.across_sides`).
        seeds: Faces in the order the search restarts from them; faces left out are never seeds
            and are only reached from seeds (label 0 if none reaches them).

    Returns:
        Per-face labels 1..K numbered in seed order, 0 for faces no seed reaches.

    Raises:
        RuntimeError: scipy's search did not discover nodes in the order this relies on.

    """
    n_faces, width = targets.shape
    n_seeds = len(seeds)
    labels = np.zeros(n_faces, dtype=np.int32)
    if n_seeds == 0:
        return labels
    n = n_faces + n_seeds
    # Rows of equal length, the faces' first: a face's own place leads to itself, which the
    # search has visited by then. The virtual rows follow as they are, each its seed and then the
    # next virtual node, in the order the search must take them.
    size = width * n_faces
    index = np.int32 if size + 2 * n_seeds < 2**31 else np.int64
    indices = np.empty(size + 2 * n_seeds - 1, dtype=index)
    indices[:size] = targets.ravel()
    indices[size::2] = seeds
    indices[size + 1 :: 2] = n_faces + np.arange(1, n_seeds)
    ends = size + np.minimum(2 * np.arange(1, n_seeds + 1), 2 * n_seeds - 1)
    indptr = np.concatenate([np.arange(0, size + 1, width), ends]).astype(index)
    # The search reads no weights: one float64 (scipy's own type, so no copy) seen as all of them.
    weights = np.broadcast_to(np.float64(1.0), indices.shape)
    graph = sp.csr_matrix((weights, indices, indptr), shape=(n, n))
    found = np.asarray(
        depth_first_order(graph, n_faces, directed=True, return_predecessors=False),
        dtype=np.int64,
    )
    is_virtual = found >= n_faces
    if np.any(np.diff(found[is_virtual]) != 1):
        raise RuntimeError('depth-first search did not follow the seed chain in order')
    run = np.cumsum(is_virtual)[~is_virtual]
    faces = found[~is_virtual]
    # Runs whose seed an earlier run had already taken are empty: renumber the rest 1..K.
    present = np.zeros(n_seeds + 1, dtype=bool)
    present[run] = True
    renumber = np.cumsum(present).astype(np.int32)
    labels[faces] = renumber[run]
    return labels
