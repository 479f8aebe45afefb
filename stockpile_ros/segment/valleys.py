"""Valleys between rocks, and regions split along them.

How far each face lies below its smoothed surroundings (at radii in edge lengths or in the
smallest rock's b), and the split of a region along a valley that runs across it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy import sparse

from .adjacency import FaceAdjacency, FaceGeometry
from .cleanup import split_into_parts

__all__ = [
    'COARSE_CELLS',
    'COARSE_MIN_EDGES',
    'MAX_SMOOTHING_PASSES',
    'smooth_normals',
    'smoothing_passes',
    'split_at_valleys',
    'valley_depths',
]


F64 = npt.NDArray[np.float64]
I32 = npt.NDArray[np.int32]


#: Most rounds of Laplacian smoothing ``valley_depths`` runs (a radius of 32 edge lengths): a
#: degenerate mesh (a tiny median edge) or a large rock of interest on a fine mesh cannot make it
#: run for ever.
MAX_SMOOTHING_PASSES = 2 * 32**2


#: Cells across a smoothing radius in ``valley_depths``'s coarse graph, and the least cell (in
#: median edge lengths) for which the coarse graph is used instead of the mesh.
COARSE_CELLS = 3.0


COARSE_MIN_EDGES = 1.5


def smooth_normals(geom: FaceGeometry, adj: FaceAdjacency, rounds: int) -> npt.NDArray[np.float64]:
    """Return the face normals averaged ``rounds`` times with their edge neighbours', by area."""
    normals = geom.normals
    for _ in range(rounds):
        weighted = normals * geom.areas[:, None]
        acc = weighted.copy()
        for axis in range(3):
            acc[:, axis] += np.bincount(adj.i, weights=weighted[adj.j, axis], minlength=adj.n_faces)
            acc[:, axis] += np.bincount(adj.j, weights=weighted[adj.i, axis], minlength=adj.n_faces)
        norm = np.linalg.norm(acc, axis=1, keepdims=True)
        normals = np.where(norm > 0, acc / np.where(norm > 0, norm, 1.0), 0.0)
    return normals


def smoothing_passes(radius: float, edge: float) -> int:
    """Return the rounds of uniform Laplacian smoothing that spread a vertex over ``radius``.

    ``k`` rounds over edges of length ``edge`` spread a vertex with a standard deviation of about
    ``edge sqrt(k / 2)``, so ``k = 2 (radius / edge)^2``, at least 1 and at most
    ``MAX_SMOOTHING_PASSES`` (a zero or tiny ``edge`` gives the most).
    """
    # The ratio is compared before it is squared: the square of a huge ratio overflows.
    ratio = radius / edge if edge > 0 else math.inf
    if ratio >= math.sqrt(MAX_SMOOTHING_PASSES / 2.0):
        return MAX_SMOOTHING_PASSES
    return max(1, round(2.0 * ratio**2))


def _neighbour_mean(i: npt.NDArray[np.int64], j: npt.NDArray[np.int64], n: int) -> Any:
    """Return the matrix that replaces each of ``n`` vertices by the mean of its neighbours.

    Args:
        i: One end of every edge (an edge may come more than once).
        j: The other end.
        n: Number of vertices.

    """
    # Duplicates are summed: the matrix only marks neighbours. Built one way and added to its
    # transpose: a mesh's edges go in once each, not once per direction.
    link = sparse.csr_matrix((np.ones(len(i)), (i, j)), shape=(n, n))
    link = (link + link.T).tocsr()
    # Each row divided by its count of neighbours, in place (a product with a diagonal matrix
    # would build the matrix again).
    degree = np.diff(link.indptr)
    link.data[:] = np.repeat(1.0 / np.maximum(degree, 1), degree)
    return link


def _coarse_smooth(
    vertices: F64,
    i: npt.NDArray[np.int64],
    j: npt.NDArray[np.int64],
    radius: float,
    cell: float,
    spread: float,
) -> F64:
    """Smoothed position of each vertex at ``radius``, smoothed on a coarser graph of cells.

    The vertices are gathered into cubes of side ``cell`` (each cube one node at the mean of its
    vertices, two nodes linked where a mesh edge links their vertices), the nodes are smoothed
    as ``valley_depths`` smooths vertices, and each vertex takes its node's smoothed position.
    A round spreads a node over the mean squared length of the links, so the rounds are those
    of ``smoothing_passes`` for links of the length that spreads as far as ``spread`` says a
    median edge of the mesh does. The rounds fall with the square of the cell and so do the
    nodes: a radius of many edge lengths costs a small share of smoothing the mesh itself.

    Args:
        vertices: Nx3 vertex positions [m].
        i: One end of every mesh edge.
        j: The other end.
        radius: Smoothing scale [m].
        cell: Side of the cubes [m].
        spread: The mesh's mean squared edge length over its median edge length squared.

    """
    key3 = np.floor((vertices - vertices.min(axis=0)) / cell).astype(np.int64)
    span = key3.max(axis=0) + 1
    key = (key3[:, 0] * span[1] + key3[:, 1]) * span[2] + key3[:, 2]
    _, node = np.unique(key, return_inverse=True)
    node = node.ravel()
    m = int(node.max()) + 1
    count = np.bincount(node, minlength=m).astype(np.float64)
    total = [np.bincount(node, weights=vertices[:, k], minlength=m) for k in range(3)]
    pos: F64 = np.stack(total, axis=1).astype(np.float64) / count[:, None]
    ni, nj = node[i], node[j]
    cross = ni != nj
    ni, nj = ni[cross], nj[cross]
    if not len(ni):
        return np.asarray(pos[node])
    step = _neighbour_mean(ni, nj, m)
    # Every link once each way in the matrix, however many mesh edges made it.
    rows = np.repeat(np.arange(m), np.diff(step.indptr))
    link2 = np.sum((pos[rows] - pos[step.indices]) ** 2, axis=1)
    length = math.sqrt(float(np.mean(link2)) / spread)
    moved = pos
    for _ in range(smoothing_passes(radius, length)):
        moved = step @ moved
    return np.asarray(vertices + (moved - pos)[node])


def valley_depths(
    vertices: F64,
    faces: npt.NDArray[np.int64],
    geom: FaceGeometry,
    radii: Sequence[float],
    edge: float,
    edges: tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]],
) -> list[F64]:
    """Depth of each face under its smoothed surroundings, at each scale in ``radii``.

    Each vertex is compared with the average of its neighbourhood, found by rounds of uniform
    Laplacian smoothing (see ``smoothing_passes``). The depth of a vertex is how far its smoothed
    position lies above it along its normal (positive in a valley, negative on a crest); a face's
    is the mean of its vertices'. Unlike Eq. 2, which compares neighbouring faces only, this sees
    a crease that Poisson spread over several faces. Radii under ``COARSE_MIN_EDGES`` times
    ``COARSE_CELLS`` edge lengths are smoothed on the mesh, once up to the largest of them and
    read off at each smaller one on the way; larger ones on a coarser graph of cells
    ``1 / COARSE_CELLS`` of the radius across (see ``_coarse_smooth``), which the smoothed
    surface at that radius does not resolve.

    Args:
        vertices: Nx3 vertex positions [m].
        faces: Mx3 triangles.
        geom: Face normals and areas (the vertex normals are their area-weighted means).
        radii: Scales of the neighbourhood [m].
        edge: Median edge length of the mesh [m] (see ``median_edge``).
        edges: The mesh's edges between vertices, each once (``FaceAdjacency.vertex_edges``).

    Returns:
        Per face depths [m], one array per radius, in the order of ``radii``.

    """
    n = len(vertices)
    weighted = geom.normals * geom.areas[:, None]
    a = faces.ravel()
    vn: F64 = np.stack(
        [np.bincount(a, weights=np.repeat(weighted[:, k], 3), minlength=n) for k in range(3)],
        axis=1,
    ).astype(np.float64)
    vn /= np.maximum(np.linalg.norm(vn, axis=1, keepdims=True), 1e-12)
    b = faces[:, [1, 2, 0]].ravel()
    step: Any = None
    smooth, done = vertices, 0
    # Each interior edge twice, a border edge once: the mean weighs them as the smoothing does.
    # Summed a coordinate at a time: gathering whole rows of ``vertices`` costs four times more.
    length2 = 0.0
    for column in np.ascontiguousarray(vertices.T):
        side = column[a] - column[b]
        length2 += float(side @ side)
    spread = length2 / len(a) / edge**2 if edge > 0 and len(a) else 1.0
    out: dict[int, F64] = {}
    for k in sorted(range(len(radii)), key=lambda k: radii[k]):
        cell = radii[k] / COARSE_CELLS
        if edge > 0 and cell >= COARSE_MIN_EDGES * edge:
            at = _coarse_smooth(vertices, *edges, radii[k], cell, spread)
        else:
            if step is None:
                step = _neighbour_mean(*edges, n)
            for _ in range(smoothing_passes(radii[k], edge) - done):
                smooth = step @ smooth
                done += 1
            at = smooth
        deep = np.einsum('ij,ij->i', at - vertices, vn)
        out[k] = (deep[faces[:, 0]] + deep[faces[:, 1]] + deep[faces[:, 2]]) / 3.0
    return [out[k] for k in range(len(radii))]


def split_at_valleys(
    labels: I32, adj: FaceAdjacency, areas: F64, deep: npt.NDArray[np.bool_], min_share: float
) -> I32:
    """Split each region that its ``deep`` faces cut into two or more large parts.

    Within a region, the faces that are not deep fall into connected parts. Where two or more of
    them each hold at least ``min_share`` of the region's area, each becomes a region of its own
    and the rest of the region (the valley and any small parts) is handed back to them, within
    the region only (see ``split_into_parts``). Other regions are left alone.

    Args:
        labels: Per-face region ids (0 = excluded).
        adj: Face adjacency.
        areas: Face areas.
        deep: Per face, whether it lies in a valley.
        min_share: Smallest share of its region's area for a part to count.

    Returns:
        The labels, split regions under new ids.

    """
    least = np.bincount(labels, weights=areas) * np.float64(min_share)
    return split_into_parts(labels, adj, areas, ~deep, least)
