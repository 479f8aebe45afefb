"""Segmentation of a stockpile mesh into rocks: the paper's search (Eq. 2) plus optional clean-up.

Two presets of :class:`SegmentParams`:

* ``paper``: the published rule as written: face normals, ``t = 0.7``, seeds in face order, restarts
  until the mesh is covered, nothing removed or merged. Every region is reported, however small.
* ``default``: what measured best against ground truth on reconstructed simulator piles: every face
  within a few edge lengths of the ground plane that does not face down is ground and is excluded
  first (Poisson rounds the foot of each rock into a skirt that the search would otherwise take
  into the rock: 10-27 % of a rock's area on one pile); faces in a concave valley at the scale of a
  few edge lengths are kept out of the search too (see ``valley_depths``: where two rocks touch,
  Poisson bridges the crevice with a surface that is smooth face to face, and the search leaked
  through it: on seven piles, 21 of its regions had under 85 % of their area on a single rock);
  ``t = 0.93`` (stricter than the paper's 0.7 and the authors' code's 0.81: Poisson rounds contact
  creases, and a looser test merges touching rocks); seeds from the most convex faces; every
  region smaller than a share of the smallest rock of interest is a fragment and is merged into
  the neighbouring region it shares the longest border with; the valley faces are handed back to
  the regions they border, growing from both sides of a valley until they meet; a region that
  faces down and borders only ground is dropped (an underside cut off from its rock); then
  neighbouring regions whose union stays convex across their shared border are joined (on
  reconstructed piles, noise stops the search inside single rocks: this took precision from 0.38
  to 1.0 on one and from 0.81 to 1.0 on another, see ``merge_convex_borders``); last, a region
  that a wider valley cuts into two or more large parts is split into them (two touching rocks
  that the search joined through a gap in the narrower valley, see ``split_at_valleys``).

Scale: no length of the default mode is absolute, so a pile of sand grains and one of boulders
meshed alike segment alike. The skirt Poisson leaves round the foot of a rock is a few of its
cells high, so the ground tolerance is a multiple of the mesh's median edge length. What is a
rock and what a fragment, and how wide the crevices between rocks are, depend on the smallest
rock of interest, ``min_rock_b`` (given, from the class being checked, or a number of edge
lengths, see :func:`rock_scale`): the fragment area and the valley scales are in its units, and
the valley depths are shares of their scale (a crease angle, not a length). Nothing depends on
the size of the whole pile.

Resolution: a reconstructed mesh shows nothing finer than a few of its edges (the noise of the
dense points is smoothed by Poisson over about that scale), so no scale goes under it: the
smallest rock of interest is never under ``min_rock_edges`` edge lengths, and the valley and split
radii never under ``valley_min_edges`` and ``split_min_edges``. A smaller rock asked for (by a
class, say) keeps the larger scales; :attr:`RockScale.requested` records what was asked.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, replace
from typing import Annotated, Any, Literal

import numpy as np
import numpy.typing as npt
from scipy import sparse
from scipy.sparse.csgraph import connected_components
from scipy.spatial import ConvexHull, QhullError

from ..ranges import Range
from .adjacency import FaceAdjacency, FaceGeometry, face_adjacency, face_geometry
from .criterion import PAPER_THRESHOLD, edge_scores
from .region import grow_regions

F64 = npt.NDArray[np.float64]

__all__ = [
    'MAX_SMOOTHING_PASSES',
    'RESOLVABLE_EDGES',
    'RockScale',
    'SegmentParams',
    'Segmentation',
    'class_min_rock_b',
    'drop_facing_down',
    'hand_back',
    'median_edge',
    'merge_convex_borders',
    'merge_fragments',
    'rock_scale',
    'segment_mesh',
    'smoothing_passes',
    'split_at_valleys',
    'valley_depths',
]

Mode = Literal['paper', 'default']
BORDER_SAMPLES = 256
HULL_SAMPLES = 2000
#: Most faces whose edges give the median edge length (an even stride of the mesh's).
EDGE_SAMPLES = 65536
I32 = npt.NDArray[np.int32]
#: Most rounds of Laplacian smoothing ``valley_depths`` runs (a radius of 32 edge lengths): a
#: degenerate mesh (a tiny median edge) or a large rock of interest on a fine mesh cannot make it
#: run for ever.
MAX_SMOOTHING_PASSES = 2 * 32**2
#: Cells across a smoothing radius in ``valley_depths``'s coarse graph, and the least cell (in
#: median edge lengths) for which the coarse graph is used instead of the mesh.
COARSE_CELLS = 3.0
COARSE_MIN_EDGES = 1.5
#: The least ``min_rock_edges`` can be set to: a rock under this many median edge lengths across
#: cannot be told from mesh noise even on a noise-free mesh.
RESOLVABLE_EDGES = 4.0
#: When a class is checked, the smallest rock of interest is this share of the smallest size the
#: class names (the lower limit of its D15): the rocks under D15 carry 15 % of the mass and must
#: be counted for D15 to come out right.
CLASS_MIN_SHARE = 0.5


@dataclass(frozen=True)
class SegmentParams:
    """Every knob of the segmentation. Paper values in brackets; each length says its unit.

    Attributes:
        mode: Name of the preset these values came from. As a parameter: the preset that gives
            every other ``segment`` value not set explicitly.
        threshold: ``t`` of Eq. 2 [0.7; the authors' code used 0.81; 0.93 measured best here: on
            four reconstructed piles 0.90 merged touching rocks (recall 0.64 on one), 0.95 began
            to split single rocks].
        seed_order: ``"index"`` restarts at the lowest-numbered unvisited face [the paper names no
            order]; ``"convex"`` at the unvisited face whose outgoing edges score highest on average
            (the authors' code seeded among the most convex faces).
        normal_smoothing: Rounds of area-weighted averaging of each face normal with its neighbours'
            before the test [0].
        exclude_ground: Give faces on the ground plane label 0 and keep them out of the search [no;
            the authors removed the ground by hand].
        min_rock_b: Intermediate dimension b of the smallest rock of interest [m]; 0: half the
            smallest size of the class being checked (the lower limit of its D15) when a class is
            checked, else ``min_rock_edges`` median edge lengths. Never taken under
            ``min_rock_edges`` edge lengths.
        min_rock_edges: The smallest rock a mesh resolves: the smallest rock of interest when
            neither ``min_rock_b`` nor a class gives it, and its floor when one does [in median
            edge lengths; at least ``RESOLVABLE_EDGES`` (4)]. On reconstructed meshes the
            search's pieces of single rocks that no clean-up joins reach about this size
            (12-55 cm2, square roots of 9-19 edge lengths, on the demo pile): a class-derived
            ``min_rock_b`` of 12 edge lengths (class I on the demo pile, 3.8 mm edges) took the
            result from 14 to 18 rocks there even with every other floor; 20 kept 14.
        ground_tolerance_edges: Height above ``z = 0`` under which a face is ground [in median
            edge lengths; 2 is the 1 cm fitted on reconstructed piles at the 4-5 mm median edge of
            a depth-9 Poisson mesh of a simulator scene (4.3 mm on the demo scene, 3.4-4.9 mm on
            bench/bench_scale.py's piles)].
        ground_min_nz: Smallest normal z component of a ground face (0: any face that does not
            face down; the skirt Poisson puts round the foot of a rock slopes).
        min_region_share: Regions of less area than this share of the plan area of the smallest
            rock of interest (a disc of diameter ``min_rock_b``) are fragments; 0 keeps every
            region [in units of ``pi / 4 min_rock_b^2``] [0; the authors' code dropped regions
            under 1 % of all faces, a rule that caps a pile at about 100 rocks]. 1: a rock of
            interest shows at least its plan area unless it is mostly hidden. On reconstructed
            piles the pieces of single rocks that survive the convex join are up to about that
            size: with 0.25 the demo pile gave 24 rocks for 14 (12 false, every one on a true
            rock, 13-170 cm2) and one of 12 rocks gave 30; 0.5 gave 15 and 17, 1.0 14 and 14
            (2 and 3 false), 1.5 and 2 the same. On bench/bench_scale.py's coarse pile (150 rocks
            of 11-22 edge lengths across) discs of 10 to 20 edge lengths across lost no rock
            (1.0 of the default 20 edges: recall/precision 0.986/0.989 on coarse, 0.990/0.992 on
            many, as with 0.25), discs of 28 and 30 lost 32 and 45.
        merge_fragments: Merge fragments into the neighbouring region they share the most edges
            with; when off, or when a fragment has no neighbour, it gets label 0 [off].
        drop_facing_down: Give label 0 to a region that borders no other region (only ground)
            and whose area-weighted mean normal points down [off]: the cameras look down on a
            pile, so a rock standing alone on the ground shows its top; a lone region facing down
            is an underside or overhang cut off from its rock by a gap in the mesh. On two
            reconstructed piles such regions (2047 faces, median normal z -0.19, on a 12-rock
            pile; 1224 faces, -0.29, on an 11-rock one) were reported as false rocks. Regions
            facing down that border others are left alone: on bench/bench_scale.py's many pile,
            merging those into a neighbour too gave 123 segments for 150 rocks (precision 0.81).
        merge_convex: After the fragment merge, join neighbouring regions whose union is convex
            across their shared border (see ``merge_convex_borders``) [off]: on a
            reconstructed mesh, noise stops the search inside single rocks.
        border_depth: Largest median depth of the shared border under the convex hull of the
            union (along the border's outward normal), for a join [in units of the square root
            of the smaller region's area]. On four reconstructed piles 0.12 joined every split
            rock and no touching rocks; 0.16 began to join touching rocks, 0.05 left splits.
        border_min_edges: Borders shorter than this many face edges are never joined (a corner
            contact says little about the surface between the regions).
        valley_depth_ratio: Faces whose vertices lie deeper than this under their smoothed
            surroundings are valley faces, kept out of the search and handed back to the regions
            they border afterwards; 0 disables [in units of the valley radius, a crease angle:
            0.067 is the 0.5 mm at 7.5 mm measured on reconstructed piles] [0]. On seven
            reconstructed piles (79 matched rocks) 0.5 mm took recall from 0.86 to 0.90, the
            median b error from 7.0 % to 5.4 % and the mean D50 error from 9.8 % to 4.3 %; 0.3 mm
            and 0.7 mm did worse on b or D50.
        valley_radius_b: Scale of the smoothed surroundings: the standard deviation of the
            smoothing kernel [in units of ``min_rock_b``; on reconstructed piles (depth-9 meshes,
            4-5 mm edges) 7.5 mm, about 1.5 edge lengths, measured as well as 5 and 10 mm: 0.075
            keeps it there when ``min_rock_b`` comes from the mesh]. A crease is only seen at a
            scale wider than the rounding Poisson gave it, and the crevices between larger rocks
            are wider. Never under ``valley_min_edges`` edge lengths.
        valley_min_edges: Floor of the valley radius [in median edge lengths]. On flat ground of
            three reconstructed piles (3.8, 2.0, 2.35 mm edges) the depth under the smoothed
            surface grows with the radius up to about 3 edge lengths (the noise of the dense
            points is correlated over a few cells) and then levels off near 0.15 edge lengths,
            while the valley depth threshold keeps growing with the radius: 11-17 % of the flat
            faces read as valley at 1 edge length, 9-15 % at 1.5, 4-6 % at 3, 2-5 % at 4, where
            the threshold clears the 95th percentile of the flat ground's depth. On the 12-rock
            pile of 2.0 mm edges, 1.5 edge lengths (those of a 20-edge rock of interest) left 3
            false rocks, 2.5 to 4 left 1; on the demo pile, 3 joined two touching rocks (D50
            +8 %), 2.5 and 4 did not, and 4 found one rock more (recall 0.93 against 0.86). The
            7.5 mm of the absolute rule were 2 and 3.7 edge lengths on those two piles.
        split_depth_ratio: Faces deeper than this under their surroundings at the scale
            ``split_radius_b`` cut a region; where they cut it into two or more parts of at
            least ``split_min_share`` of its area each, the parts become regions of their own (see
            ``split_at_valleys``); 0 disables [in units of the split radius] [0]. On twelve
            reconstructed piles 1 mm at 15 mm split one region, two touching rocks joined through
            a gap in the narrower valley (recall 0.905 -> 0.912, median b error 5.1 % -> 4.8 %,
            worst D50 error 16.4 % -> 6.9 %); 0.8 mm and 1.3 mm measured the same or better,
            0.6 mm began to split single rocks.
        split_radius_b: Scale of the surroundings for ``split_depth_ratio`` [in units of
            ``min_rock_b``; 0.15 is the 15 mm (3 edge lengths) measured on reconstructed piles
            when ``min_rock_b`` comes from the mesh]. Never under ``split_min_edges`` edge lengths.
        split_min_edges: Floor of the split radius [in median edge lengths; twice
            ``valley_min_edges``, as ``split_radius_b`` is twice ``valley_radius_b``].
        split_min_share: Smallest share of a region's area that a part needs to be split off
            (0.2 measured the same as 0.1).

    """

    mode: Mode = 'default'
    threshold: Annotated[float, Range(-1.0, 2.0)] = 0.93
    seed_order: Literal['index', 'convex'] = 'convex'
    normal_smoothing: Annotated[int, Range(0, 100)] = 0
    exclude_ground: bool = True
    min_rock_b: Annotated[float, Range(0.0, 100.0)] = 0.0
    min_rock_edges: Annotated[float, Range(RESOLVABLE_EDGES, 10_000.0)] = 20.0
    ground_tolerance_edges: Annotated[float, Range(0.0, 1000.0)] = 2.0
    ground_min_nz: Annotated[float, Range(0.0, 1.0)] = 0.0
    min_region_share: Annotated[float, Range(0.0, 100.0)] = 1.0
    merge_fragments: bool = True
    drop_facing_down: bool = True
    merge_convex: bool = True
    border_depth: Annotated[float, Range(0.0, 10.0)] = 0.12
    border_min_edges: Annotated[int, Range(0, 100_000_000)] = 5
    valley_depth_ratio: Annotated[float, Range(0.0, 10.0)] = 0.067
    valley_radius_b: Annotated[float, Range(0.001, 1.0)] = 0.075
    valley_min_edges: Annotated[float, Range(0.0, 100.0)] = 4.0
    split_depth_ratio: Annotated[float, Range(0.0, 10.0)] = 0.067
    split_radius_b: Annotated[float, Range(0.001, 1.0)] = 0.15
    split_min_edges: Annotated[float, Range(0.0, 100.0)] = 8.0
    split_min_share: Annotated[float, Range(0.0, 0.5)] = 0.1

    @classmethod
    def paper(cls) -> SegmentParams:
        """Return the published rule: ``t = 0.7``, face normals, index-order seeds, no clean-up."""
        return cls(
            mode='paper',
            threshold=PAPER_THRESHOLD,
            seed_order='index',
            normal_smoothing=0,
            exclude_ground=False,
            min_region_share=0.0,
            merge_fragments=False,
            drop_facing_down=False,
            merge_convex=False,
            valley_depth_ratio=0.0,
            split_depth_ratio=0.0,
        )

    @classmethod
    def preset(cls, mode: Mode, **overrides: Any) -> SegmentParams:
        """Return the ``mode`` preset with some fields replaced (``None`` values are ignored)."""
        base = cls.paper() if mode == 'paper' else cls()
        return replace(base, **{k: v for k, v in overrides.items() if v is not None})

    def as_dict(self) -> dict[str, Any]:
        """Plain dict for report.json."""
        return asdict(self)


@dataclass(frozen=True)
class RockScale:
    """The lengths a segmentation was measured against.

    Attributes:
        edge: Median edge length of the mesh [m] (0 when every edge is degenerate).
        min_rock_b: Intermediate dimension b of the smallest rock of interest [m].
        source: Where ``min_rock_b`` came from: ``"parameter"``, ``"class"`` or ``"mesh"``.
        requested: The smallest rock of interest asked for [m]; ``min_rock_b`` is larger when
            the mesh does not resolve it (see ``SegmentParams.min_rock_edges``).
        valley_radius: Scale of the valley faces (``SegmentParams.valley_radius_b``) [m].
        split_radius: Scale of the valleys that split a region (``split_radius_b``) [m].

    """

    edge: float
    min_rock_b: float
    source: Literal['parameter', 'class', 'mesh']
    requested: float
    valley_radius: float
    split_radius: float

    def as_dict(self) -> dict[str, Any]:
        """Plain dict for report.json."""
        return asdict(self)


@dataclass(frozen=True)
class Segmentation:
    """Result of :func:`segment_mesh`.

    Attributes:
        labels: Per-face rock id 1..K (0 = ground or unassigned), numbered by decreasing face count.
        faces: The Mx3 triangles segmented.
        geometry: Face centroids, (raw) normals and areas.
        adjacency: Face adjacency of the whole mesh.
        passing: Per directed edge of ``adjacency.src -> adjacency.dst``, whether Eq. 2 passed (with
            the normals actually used; False where an end is excluded ground).
        raw_regions: Number of regions the search itself produced, before any clean-up.
        params: The parameters used.
        scale: The mesh's edge length and the smallest rock of interest the lengths of ``params``
            are multiples of.

    """

    labels: I32
    faces: npt.NDArray[np.int64]
    geometry: FaceGeometry
    adjacency: FaceAdjacency
    passing: npt.NDArray[np.bool_]
    raw_regions: int
    params: SegmentParams
    scale: RockScale


def median_edge(vertices: F64, faces: npt.NDArray[np.int64]) -> float:
    """Median length of the mesh's face edges, degenerate (zero-length) edges left out [m].

    Returns:
        The median, 0 when the mesh has no edge of non-zero length.

    """
    # An even stride of faces gives the median of a million-face mesh to a fraction of a percent
    # at a small share of the cost; the same faces are picked whatever the mesh's size in metres.
    tri = vertices[faces[:: max(1, -(-len(faces) // EDGE_SAMPLES))]]
    length = np.linalg.norm(tri - tri[:, [1, 2, 0]], axis=2).ravel()
    length = length[length > 0]
    return float(np.median(length)) if len(length) else 0.0


def class_min_rock_b(spec: Mapping[str, Any]) -> float | None:
    """Smallest rock of interest for checking a class: half its smallest lower size limit.

    Args:
        spec: A class entry of the class table (``limits`` in metres, see ``check_class``).

    Returns:
        ``CLASS_MIN_SHARE`` times the smallest lower limit [m], None when the class has none.

    """
    lows = [float(lo) for lo, _ in spec.get('limits', {}).values() if lo is not None]
    return CLASS_MIN_SHARE * min(lows) if lows else None


def rock_scale(
    params: SegmentParams, edge: float, spec: Mapping[str, Any] | None = None
) -> RockScale:
    """Return the smallest rock of interest: ``min_rock_b``, else the class's, else the mesh's.

    Args:
        params: ``min_rock_b`` (0: not given) and ``min_rock_edges``.
        edge: The mesh's median edge length [m].
        spec: The class being checked, or None.

    Returns:
        The scale; ``min_rock_b`` is never under ``min_rock_edges`` edge lengths, the valley and
        split radii never under ``valley_min_edges`` and ``split_min_edges``.

    """
    floor = params.min_rock_edges * edge
    source: Literal['parameter', 'class', 'mesh'] = 'mesh'
    requested = floor
    from_class = class_min_rock_b(spec) if spec is not None else None
    if params.min_rock_b > 0:
        source, requested = 'parameter', params.min_rock_b
    elif from_class is not None:
        source, requested = 'class', from_class
    b = max(requested, floor)
    return RockScale(
        edge,
        b,
        source,
        requested,
        max(params.valley_radius_b * b, params.valley_min_edges * edge),
        max(params.split_radius_b * b, params.split_min_edges * edge),
    )


def _smooth_normals(geom: FaceGeometry, adj: FaceAdjacency, rounds: int) -> npt.NDArray[np.float64]:
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
    # Duplicates are summed: the matrix only marks neighbours.
    link = sparse.csr_matrix(
        (np.ones(2 * len(i)), (np.concatenate([i, j]), np.concatenate([j, i]))), shape=(n, n)
    )
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
    links = np.unique(np.minimum(ni, nj) * m + np.maximum(ni, nj))
    lo, hi = links // m, links % m
    length = math.sqrt(float(np.mean(np.sum((pos[lo] - pos[hi]) ** 2, axis=1))) / spread)
    step = _neighbour_mean(lo, hi, m)
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
    length2 = np.sum((vertices[a] - vertices[b]) ** 2, axis=1)
    spread = float(np.mean(length2)) / edge**2 if edge > 0 else 1.0
    out: dict[int, F64] = {}
    for k in sorted(range(len(radii)), key=lambda k: radii[k]):
        cell = radii[k] / COARSE_CELLS
        if edge > 0 and cell >= COARSE_MIN_EDGES * edge:
            at = _coarse_smooth(vertices, a, b, radii[k], cell, spread)
        else:
            if step is None:
                step = _neighbour_mean(a, b, n)
            for _ in range(smoothing_passes(radii[k], edge) - done):
                smooth = step @ smooth
                done += 1
            at = smooth
        deep = np.einsum('ij,ij->i', at - vertices, vn)
        out[k] = np.asarray(deep[faces].mean(axis=1))
    return [out[k] for k in range(len(radii))]


def hand_back(labels: I32, adj: FaceAdjacency, free: npt.NDArray[np.bool_]) -> I32:
    """Give unlabelled ``free`` faces the label of a labelled neighbour, front by front.

    Every round each free face next to a labelled face takes its label, so a band between two
    regions is split where the fronts from both sides meet.
    """
    labels = labels.copy()
    src, dst = adj.src, adj.dst
    open_edge = free[dst] & (labels[dst] == 0)
    src, dst = src[open_edge], dst[open_edge]
    while True:
        take = labels[src] > 0
        if not take.any():
            return labels
        labels[dst[take]] = labels[src[take]]
        left = labels[dst] == 0
        src, dst = src[left], dst[left]


def merge_fragments(
    labels: I32, adj: FaceAdjacency, areas: F64, min_area: float, merge: bool
) -> I32:
    """Merge regions of less area than ``min_area`` into the neighbour they share most edges with.

    A fragment only moves into a neighbour that ranks higher by (area, id), so merges never cycle
    and the lowest-ranked fragment always moves: each round makes progress. Fragments with no
    labelled neighbour (all fragments when ``merge`` is off) get label 0.

    Args:
        labels: Per-face region ids (0 = excluded).
        adj: Face adjacency.
        areas: Face areas.
        min_area: Regions under this area are fragments.
        merge: Whether fragments are merged (else they get label 0).

    Returns:
        The labels, fragments merged or cleared.

    """
    labels = labels.copy()
    if min_area <= 0:
        return labels
    while True:
        sizes = np.bincount(labels, weights=areas, minlength=int(labels.max()) + 1)
        small = (sizes < min_area) & (np.bincount(labels, minlength=len(sizes)) > 0)
        small[0] = False
        if not small.any():
            return labels
        a, b = labels[adj.src], labels[adj.dst]
        cross = (a != b) & small[a] & (b > 0)
        if not merge or not cross.any():
            labels[small[labels]] = 0
            return labels
        pair, count = np.unique(np.stack([a[cross], b[cross]], axis=1), axis=0, return_counts=True)
        order = np.lexsort((-count, pair[:, 0]))
        pair = pair[order]
        best = np.ones(len(pair), dtype=bool)
        best[1:] = pair[1:, 0] != pair[:-1, 0]
        frag, into = pair[best, 0], pair[best, 1]
        up = (sizes[into] > sizes[frag]) | ((sizes[into] == sizes[frag]) & (into > frag))
        target = np.arange(len(sizes))
        target[frag[up]] = into[up]
        while True:
            nxt = target[target]
            if np.array_equal(nxt, target):
                break
            target = nxt
        isolated = small.copy()
        isolated[pair[:, 0]] = False
        target[isolated] = 0
        labels = target[labels].astype(np.int32)


def drop_facing_down(labels: I32, adj: FaceAdjacency, lift: F64) -> I32:
    """Give label 0 to each region that faces down on the whole and borders no other region.

    Args:
        labels: Per-face region ids (0 = excluded).
        adj: Face adjacency.
        lift: Per face, its area times the z component of its normal: a region faces down when
            the sum over its faces is negative.

    Returns:
        The labels, such regions cleared.

    """
    down = np.bincount(labels, weights=lift) < 0
    down[0] = False
    a, b = labels[adj.src], labels[adj.dst]
    down[a[(a != b) & (b > 0)]] = False
    return np.where(down[labels], 0, labels).astype(np.int32)


def _hull_points(points: F64) -> F64:
    """Return up to ``HULL_SAMPLES`` vertices of the convex hull of ``points``, evenly strided.

    On a smooth rock nearly every vertex is a hull vertex, and Qhull's cost grows with the hull's
    size: the hull is taken of an even stride of at most ``2 HULL_SAMPLES`` points, and a strided
    sample of its vertices is returned. Both put the hull within a fraction of an edge length of
    the full one at a small share of the cost.
    """
    points = points[:: -(-len(points) // (2 * HULL_SAMPLES))]
    with contextlib.suppress(QhullError, ValueError):
        points = points[ConvexHull(points).vertices]
    return points[:: -(-len(points) // HULL_SAMPLES)]


def _border_depth(union: F64, border: F64, outward: F64, size: float) -> float:
    try:
        hull = ConvexHull(union)
    except (QhullError, ValueError):
        return float('inf')
    eq = hull.equations
    # The median needs no more than a few hundred points of a long border: an even stride of them
    # keeps the points-by-facets products small.
    stride = -(-len(border) // BORDER_SAMPLES)
    border, outward = border[::stride], outward[::stride]
    # Distance from each border point along its outward normal to where it leaves the hull.
    gap = -(border @ eq[:, :3].T + eq[:, 3])
    cos = outward @ eq[:, :3].T
    with np.errstate(divide='ignore', invalid='ignore'):
        reach = np.where(cos > 1e-9, np.maximum(gap, 0.0) / cos, np.inf)
    return float(np.median(reach.min(axis=1))) / size


def merge_convex_borders(
    vertices: F64,
    geom: FaceGeometry,
    labels: I32,
    adj: FaceAdjacency,
    faces: npt.NDArray[np.int64],
    max_depth: float,
    min_edges: int,
) -> I32:
    """Join neighbouring regions whose union is convex across their shared border.

    The shared border of two parts of one convex rock lies on the convex hull of their union; the
    valley where two rocks touch lies under it. The test is the median depth of the border
    (midpoints of the centroids of the face pairs across it) under the hull of the union's
    vertices, measured along the border's outward normal, over the square root of the smaller
    region's area; the shallowest border is joined first and the depths are recomputed after each
    join.

    Args:
        vertices: Nx3 vertex positions.
        geom: Face centroids and areas.
        labels: Per-face region ids (0 = excluded).
        adj: Face adjacency.
        faces: Mx3 triangles.
        max_depth: Borders with a relative depth under this are joined.
        min_edges: Borders of fewer face edges are left alone.

    Returns:
        The merged labels (ids are those of the surviving regions).

    """
    labels = labels.copy()
    cache: dict[tuple[int, int], float] = {}
    # Each region's hull vertices, found once: the hull of a union is the hull of theirs.
    order = np.argsort(labels, kind='stable')
    bounds = np.searchsorted(labels[order], np.arange(int(labels.max()) + 2))
    hulls: dict[int, F64] = {}
    used = np.zeros(len(vertices), dtype=bool)

    def hull_of(region: int) -> F64:
        if region not in hulls:
            # The region's vertices in index order, as np.unique gives them, without a sort.
            tri = faces[order[bounds[region] : bounds[region + 1]]]
            used[tri] = True
            ids = np.flatnonzero(used)
            used[ids] = False
            hulls[region] = _hull_points(vertices[ids])
        return hulls[region]

    while True:
        a, b = labels[adj.i], labels[adj.j]
        cross = (a != b) & (a > 0) & (b > 0)
        lo, hi = np.minimum(a, b)[cross], np.maximum(a, b)[cross]
        mid = 0.5 * (geom.centroids[adj.i[cross]] + geom.centroids[adj.j[cross]])
        out = geom.normals[adj.i[cross]] + geom.normals[adj.j[cross]]
        out /= np.maximum(np.linalg.norm(out, axis=1, keepdims=True), 1e-12)
        area = np.bincount(labels, weights=geom.areas)
        pairs, inverse, count = np.unique(
            np.stack([lo, hi], axis=1), axis=0, return_inverse=True, return_counts=True
        )
        inverse = inverse.ravel()
        best, best_depth = -1, max_depth
        for k in np.flatnonzero(count >= min_edges):
            key = (int(pairs[k, 0]), int(pairs[k, 1]))
            if key not in cache:
                size = float(np.sqrt(min(area[key[0]], area[key[1]])))
                union = np.concatenate([hull_of(key[0]), hull_of(key[1])])
                sel = inverse == k
                cache[key] = _border_depth(union, mid[sel], out[sel], size)
            if cache[key] < best_depth:
                best, best_depth = int(k), cache[key]
        if best < 0:
            return labels
        keep, gone = int(pairs[best, 0]), int(pairs[best, 1])
        hulls[keep] = _hull_points(np.concatenate([hull_of(keep), hull_of(gone)]))
        labels[labels == gone] = keep
        cache = {k: d for k, d in cache.items() if keep not in k and gone not in k}


def split_at_valleys(
    labels: I32,
    adj: FaceAdjacency,
    areas: F64,
    deep: npt.NDArray[np.bool_],
    min_share: float,
) -> I32:
    """Split each region that its ``deep`` faces cut into two or more large parts.

    Within a region, the faces that are not deep fall into connected parts. Where two or more of
    them each hold at least ``min_share`` of the region's area, each becomes a region of its own
    and the rest of the region (the valley and any small parts) is handed back to them, within
    the region only (see ``hand_back``). Other regions are left alone.

    Args:
        labels: Per-face region ids (0 = excluded).
        adj: Face adjacency.
        areas: Face areas.
        deep: Per face, whether it lies in a valley.
        min_share: Smallest share of its region's area for a part to count.

    Returns:
        The labels, split regions under new ids.

    """
    m = len(labels)
    same = (labels[adj.i] == labels[adj.j]) & (labels[adj.i] > 0)
    keep = same & ~deep[adj.i] & ~deep[adj.j]
    graph = sparse.csr_matrix((np.ones(int(keep.sum())), (adj.i[keep], adj.j[keep])), shape=(m, m))
    _, part = connected_components(graph, directed=False)
    solid = (labels > 0) & ~deep
    part_area = np.bincount(part[solid], weights=areas[solid], minlength=m)
    region_area = np.bincount(labels, weights=areas)
    big = solid & (part_area[part] >= min_share * region_area[labels])
    # One key per (region, part) pair: a 1-D unique sorts far faster than rows of pairs.
    pairs = np.unique(labels[big].astype(np.int64) * m + part[big])
    regions = pairs // m
    split = np.bincount(regions, minlength=len(region_area)) >= 2
    split[0] = False
    if not split.any():
        return labels
    in_split = split[labels]
    out = np.where(in_split, 0, labels).astype(np.int32)
    sel = in_split & big
    _, new = np.unique(part[sel], return_inverse=True)
    out[sel] = int(labels.max()) + 1 + new.ravel()
    return hand_back(out, FaceAdjacency(m, adj.i[same], adj.j[same]), in_split)


def _renumber_by_size(labels: I32) -> I32:
    sizes = np.bincount(labels)
    sizes[0] = 0
    order = np.argsort(-sizes, kind='stable')
    k = int(np.count_nonzero(sizes))
    remap = np.zeros(len(sizes), dtype=np.int32)
    remap[order[:k]] = np.arange(1, k + 1, dtype=np.int32)
    return remap[labels]


def segment_mesh(
    vertices: npt.ArrayLike,
    faces: npt.ArrayLike,
    params: SegmentParams | None = None,
    spec: Mapping[str, Any] | None = None,
) -> Segmentation:
    """Segment a stockpile mesh (stockpile frame: z up, ground at ``z = 0``) into rocks.

    Args:
        vertices: Nx3 vertex positions.
        faces: Mx3 triangles, outward normals by the right-hand rule.
        params: Parameters; the ``default`` preset if None.
        spec: The class the gradation will be checked against, or None: when ``min_rock_b`` is
            0 it sets the smallest rock of interest (see ``rock_scale``).

    Returns:
        The per-face labels and what they were computed from.

    """
    p = params or SegmentParams()
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    geom = face_geometry(v, f)
    adj = face_adjacency(f, len(v))
    m = len(f)
    scale = rock_scale(p, median_edge(v, f) if m else 0.0, spec)
    edge = scale.edge
    normals = _smooth_normals(geom, adj, p.normal_smoothing)
    active = np.ones(m, dtype=bool)
    if p.exclude_ground:
        ground = (geom.centroids[:, 2] < p.ground_tolerance_edges * edge) & (
            normals[:, 2] >= p.ground_min_nz
        )
        active &= ~ground
    # One smoothing serves both scales: depths[0] is the valley's, depths[-1] the split's. A
    # mesh without a length (every edge degenerate) has no scale to look for valleys at.
    valley_radius, split_radius = scale.valley_radius, scale.split_radius
    scales = ((valley_radius, p.valley_depth_ratio), (split_radius, p.split_depth_ratio))
    radii = [r for r, d in scales if d > 0 and edge > 0]
    depths = valley_depths(v, f, geom, radii, edge) if radii else []
    valley = np.zeros(m, dtype=bool)
    if p.valley_depth_ratio > 0 and depths:
        valley = (depths[0] > p.valley_depth_ratio * valley_radius) & active
        active &= ~valley
    if active.all():
        search = adj
    else:
        inner = active[adj.i] & active[adj.j]
        search = FaceAdjacency(m, adj.i[inner], adj.j[inner])
    towards_j, towards_i = edge_scores(geom.centroids, normals, search.i, search.j)
    pass_ij, pass_ji = towards_j > p.threshold, towards_i > p.threshold
    if search is adj:
        passing = np.concatenate([pass_ij, pass_ji])
    else:
        passing = np.zeros(2 * len(adj.i), dtype=bool)
        passing[: len(adj.i)][inner] = pass_ij
        passing[len(adj.i) :][inner] = pass_ji
    if p.seed_order == 'index':
        seeds = np.flatnonzero(active)
    else:
        total = np.bincount(search.i, weights=towards_j, minlength=m) + np.bincount(
            search.j, weights=towards_i, minlength=m
        )
        count = search.neighbour_count()
        convexity = np.where(count > 0, total / np.maximum(count, 1), -np.inf)
        seeds = np.flatnonzero(active)
        seeds = seeds[np.argsort(-convexity[seeds], kind='stable')]
    src = np.concatenate([search.i[pass_ij], search.j[pass_ji]])
    dst = np.concatenate([search.j[pass_ij], search.i[pass_ji]])
    labels = grow_regions(m, src, dst, seeds)
    raw = int(labels.max()) if m else 0
    min_area = p.min_region_share * np.pi / 4.0 * scale.min_rock_b**2
    if min_area > 0:
        labels = merge_fragments(labels, search, geom.areas, min_area, p.merge_fragments)
    if valley.any():
        labels = hand_back(labels, adj, valley)
        search = adj
    if p.drop_facing_down:
        # After the valley faces are handed back: a region that reaches a rock across a valley
        # borders it and stays.
        labels = drop_facing_down(labels, adj, geom.areas * geom.normals[:, 2])
    if p.merge_convex:
        labels = merge_convex_borders(
            v, geom, labels, search, f, p.border_depth, p.border_min_edges
        )
    if p.split_depth_ratio > 0 and depths:
        deep = depths[-1] > p.split_depth_ratio * split_radius
        labels = split_at_valleys(labels, adj, geom.areas, deep, p.split_min_share)
    return Segmentation(_renumber_by_size(labels), f, geom, adj, passing, raw, p, scale)
