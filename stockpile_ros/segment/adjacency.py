"""Face geometry and face adjacency over shared edges of a triangle mesh."""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy import sparse

from .blocks import blocks

__all__ = ['FaceAdjacency', 'FaceGeometry', 'face_adjacency', 'face_geometry']

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]


@dataclass(frozen=True)
class FaceGeometry:
    """Per-face centroid, unit normal and area.

    Attributes:
        centroids: Mx3 face centroids.
        normals: Mx3 unit face normals (right-hand rule on the vertex order); zero for degenerate
        faces.
        areas: M face areas.

    """

    centroids: F64
    normals: F64
    areas: F64


@dataclass(frozen=True)
class FaceAdjacency:
    """Faces sharing an edge.

    Attributes:
        n_faces: Number of faces M.
        i: E first faces of each shared edge (``i < j``).
        j: E second faces.
        half_edges: The mesh's half-edges grouped by their smaller vertex, as the rows of a sparse
            matrix (``indptr`` per vertex, then each half-edge's larger vertex, in order), and
            per half-edge but the last whether the next one runs along the same edge; None where
            the pairs were not found from faces. :attr:`vertex_edges` is read off them.
        sides: Per pair, the side of ``i`` and the side of ``j`` they meet along (the side
            ``3 f + k`` of face ``f`` runs from its corner ``k`` to the next), so that a face's
            neighbours can be laid out by its three sides (:meth:`across_sides`); None where the
            pairs were not found from faces.

    """

    n_faces: int
    i: I64
    j: I64
    half_edges: tuple[I64, I64, npt.NDArray[np.bool_]] | None = None
    sides: tuple[I64, I64] | None = None

    # Cached: the clean-up steps ask for the directed edges once per round.
    @functools.cached_property
    def src(self) -> I64:
        """Directed edges' sources: pairs ``i -> j`` first, then ``j -> i``."""
        return np.concatenate([self.i, self.j])

    @functools.cached_property
    def dst(self) -> I64:
        """Directed edges' destinations, matching :attr:`src`."""
        return np.concatenate([self.j, self.i])

    @functools.cached_property
    def vertex_edges(self) -> tuple[I64, I64]:
        """The mesh's edges between vertices, each once: smaller vertex, larger vertex.

        Ordered by both (read off :attr:`half_edges` when asked for: the search does not need
        them).

        Raises:
            ValueError: The pairs were not found from faces.

        """
        if self.half_edges is None:
            raise ValueError('this adjacency was not found from faces: it has no vertex edges')
        indptr, other, same = self.half_edges
        first = np.ones(len(other), dtype=bool)
        first[1:] = ~same
        row = np.repeat(np.arange(len(indptr) - 1), np.diff(indptr))
        return row[first], other[first]

    def across_sides(self, to_j: npt.NDArray[np.bool_], to_i: npt.NDArray[np.bool_]) -> I64:
        """Per face and side, the neighbour across it where the pair's flag is set, else the face.

        Args:
            to_j: Per pair, whether ``i`` leads to ``j``.
            to_i: Per pair, whether ``j`` leads to ``i``.

        Returns:
            An M x 3 table: row ``f`` lists the faces ``f`` leads to, ``f`` itself in the others'
            places (a search's graph without sorting edges by face).

        Raises:
            ValueError: The pairs were not found from faces.

        """
        if self.sides is None:
            raise ValueError('this adjacency was not found from faces: it has no sides')
        side_i, side_j = self.sides
        table = np.repeat(np.arange(self.n_faces), 3)
        table[side_i] = np.where(to_j, self.j, self.i)
        table[side_j] = np.where(to_i, self.i, self.j)
        return table.reshape(-1, 3)

    def neighbour_count(self) -> I64:
        """Count the neighbours of each face."""
        return np.bincount(self.i, minlength=self.n_faces) + np.bincount(
            self.j, minlength=self.n_faces
        )


def face_geometry(vertices: npt.ArrayLike, faces: npt.ArrayLike) -> FaceGeometry:
    """Centroids, unit normals and areas of the faces of a triangle mesh."""
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    m = len(f)
    centroids, normals, areas = np.empty((m, 3)), np.empty((m, 3)), np.empty(m)
    for at in blocks(m):
        # np.take gathers rows two to three times faster than fancy indexing, same values.
        p0, p1, p2 = (np.take(v, f[at, k], axis=0) for k in range(3))
        e1, e2 = p1 - p0, p2 - p0
        # np.cross's own products in its order (the same bits), without its temporary copies.
        cross = np.empty_like(e1)
        cross[:, 0] = e1[:, 1] * e2[:, 2] - e1[:, 2] * e2[:, 1]
        cross[:, 1] = e1[:, 2] * e2[:, 0] - e1[:, 0] * e2[:, 2]
        cross[:, 2] = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
        norm = np.sqrt(np.einsum('ij,ij->i', cross, cross))
        # A degenerate face (norm 0) has a zero cross product: divided by 1 its normal is zero.
        np.divide(cross, np.where(norm > 0, norm, 1.0)[:, None], out=normals[at])
        p0 += p1
        p0 += p2
        np.divide(p0, 3.0, out=centroids[at])
        np.multiply(norm, 0.5, out=areas[at])
    return FaceGeometry(centroids=centroids, normals=normals, areas=areas)


def face_adjacency(faces: npt.ArrayLike, n_vertices: int | None = None) -> FaceAdjacency:
    """Pairs of faces sharing an edge.

    An edge shared by more than two faces (non-manifold) links them two by two in face order (the
    first with the second, the third with the fourth, and an odd last one with none), so that
    each side of a face has at most one neighbour: such edges are rare in a Poisson mesh (13 in
    the 1.08 M faces of bench/bench_segment.py's), so this only keeps odd input usable.

    Args:
        faces: Mx3 vertex indices.
        n_vertices: Number of vertices; defaults to the largest index + 1.

    """
    f = np.asarray(faces, dtype=np.int64)
    m = len(f)
    if m == 0:
        empty = np.zeros(0, dtype=np.int64)
        rows = (np.zeros(1, dtype=np.int64), empty, empty.astype(bool))
        return FaceAdjacency(0, empty, empty, rows, (empty, empty))
    nv = int(f.max()) + 1 if n_vertices is None else int(n_vertices)
    a = f.ravel()
    b = f[:, [1, 2, 0]].ravel()
    # Half-edges ordered by (smaller vertex, larger vertex, half-edge): grouped by the smaller
    # vertex with a counting sort (a sparse matrix's rows), then each vertex's few by column, the
    # half-edge's index in the column's low bits so that every column is distinct. The order is
    # that of a stable sort of the edge keys, at two thirds of its cost on a Poisson mesh. The
    # columns fit in 63 bits below about 10^8 faces.
    bits = (3 * m - 1).bit_length()
    column = (np.maximum(a, b) << bits) | np.arange(3 * m)
    rows = sparse.csr_matrix(
        (np.ones(3 * m, dtype=np.int8), (np.minimum(a, b), column)), shape=(nv, nv << bits)
    )
    # Already sorted by the conversion (it sums duplicates); said here, as the pairing needs it.
    rows.sort_indices()
    half = rows.indices & ((1 << bits) - 1)
    other = rows.indices >> bits
    same = other[1:] == other[:-1]
    # Runs of one column that meet across two rows are not the same edge.
    starts = rows.indptr[1:-1]
    same[starts[(starts > 0) & (starts < len(half))] - 1] = False
    at = np.flatnonzero(same)
    chained = at[1:] == at[:-1] + 1
    if chained.any():
        # Three or more sides along one edge: every other link of the run, from its first.
        first = np.concatenate([[True], ~chained])
        start = np.maximum.accumulate(np.where(first, np.arange(len(at)), 0))
        at = at[(np.arange(len(at)) - start) % 2 == 0]
    # Along one edge the sides come in increasing order: the pair's first face is the smaller.
    side_i, side_j = half[at], half[at + 1]
    i, j = side_i // 3, side_j // 3
    # A face that runs twice along one edge (degenerate) is no neighbour of itself.
    keep = i != j
    if not keep.all():
        i, j, side_i, side_j = i[keep], j[keep], side_i[keep], side_j[keep]
    return FaceAdjacency(m, i, j, (rows.indptr, other, same), (side_i, side_j))
