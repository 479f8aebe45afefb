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
  the neighbouring region it shares the longest border with; a region whose faces more than a
  valley radius in from its outline fall into two or more parts of a fragment's area or more is
  split into them at the necks between them (the search ran from one rock into the next through
  a gap in the valley band, see ``split_at_necks``); the valley faces are handed back to
  the regions they border, growing from both sides of a valley until they meet (those that no
  region reaches going down into the valley within about a valley radius stay out of every
  rock, see ``valley_reach``, or, with ``far_valley_pieces``, are cut by the search into pieces
  that join a rock only where convex with it); a region that faces down and borders only ground
  is dropped (an underside cut off from its rock); a region whose faces deep under its own
  convex hull cut it into two or more parts of a fragment's area or more is split into them (two
  touching rocks the search ran across where the crease between them is too shallow for the
  valley test at its radius, see ``hull_split``); then neighbouring regions whose union stays
  convex across their shared border are joined (on reconstructed piles, noise stops the search
  inside single rocks: this took precision from 0.38 to 1.0 on one and from 0.81 to 1.0 on
  another, see ``merge_convex_borders``), the fragments left out before taking part and left
  out again where joined to nothing (see ``convex_fragments``). A region that a wider valley
  cuts into two or more large parts can be split into them last (``split_depth_ratio``, see
  ``split_at_valleys``): off by default, as the neck split parts the rocks it was for and it
  cut single rough rocks.

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

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from .adjacency import FaceAdjacency, FaceGeometry, face_adjacency, face_geometry
from .cleanup import (
    drop_facing_down,
    drop_unanchored,
    hand_back,
    label_parts,
    merge_convex_borders,
    merge_fragments,
    split_at_necks,
    split_under_hulls,
)
from .criterion import edge_scores
from .ground import ground_height
from .params import RINGS_PER_EDGE, RockScale, SegmentParams, median_edge, rock_scale
from .region import grow_regions
from .valleys import smooth_normals, split_at_valleys, valley_depths

__all__ = ['STEPS', 'Segmentation', 'segment_mesh']

#: The steps of :func:`segment_mesh` in the order they run, as ``on_step`` names them.
STEPS = (
    'search',
    'fragments',
    'necks',
    'valleys near',
    'valleys all',
    'far pieces',
    'undersides',
    'hull split',
    'convex join',
    'valley split',
    'far valleys out',
)

I32 = npt.NDArray[np.int32]
F64 = npt.NDArray[np.float64]


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
        ground: Per face, the height of the open ground under it (``ground_height``) [m]; NaN
            where the ground is the plane ``z = 0``.

    """

    labels: I32
    faces: npt.NDArray[np.int64]
    geometry: FaceGeometry
    adjacency: FaceAdjacency
    passing: npt.NDArray[np.bool_]
    raw_regions: int
    params: SegmentParams
    scale: RockScale
    ground: F64


def _renumber_by_size(labels: I32) -> I32:
    sizes = np.bincount(labels)
    sizes[0] = 0
    order = np.argsort(-sizes, kind='stable')
    k = int(np.count_nonzero(sizes))
    remap = np.zeros(len(sizes), dtype=np.int32)
    remap[order[:k]] = np.arange(1, k + 1, dtype=np.int32)
    return remap[labels]


def _most_convex_first(convexity: F64, faces: npt.NDArray[np.int64]) -> npt.NDArray[np.int64]:
    """Return ``faces`` by decreasing ``convexity``, equal values in face order.

    The order of a stable sort, at half its cost on a million faces: each value becomes an
    integer in the same order (the float's bits, negatives' magnitude bits flipped), its lowest
    bits give way to the face index, and these unique keys are sorted by value alone. Values
    that differ only in the bits given up (under 2^-32 of the value on a million faces) fall in
    one run of equal keys; the few such runs are then put in order by value.
    """
    bits = max(1, int(faces.max(initial=0)).bit_length())
    # +0.0 turns -0.0 into 0.0, which a stable sort of the floats takes as equal.
    value = -convexity[faces] + 0.0
    key = value.view(np.int64)
    key = np.where(key < 0, key ^ np.int64(0x7FFF_FFFF_FFFF_FFFF), key)
    key = np.sort(((key >> bits) << bits) | faces)
    order = key & ((1 << bits) - 1)
    value = -convexity[order] + 0.0
    run = np.cumsum(np.concatenate([[True], key[1:] >> bits != key[:-1] >> bits]))
    mixed = run[1:][(run[1:] == run[:-1]) & (value[1:] != value[:-1])]
    if len(mixed):
        at = np.flatnonzero(np.isin(run, mixed))
        order[at] = order[at[np.lexsort((order[at], value[at], run[at]))]]
    return order


def _restricted(
    adj: FaceAdjacency, keep: npt.NDArray[np.bool_]
) -> tuple[FaceAdjacency, npt.NDArray[np.bool_]]:
    """Return the edges of ``adj`` between two ``keep`` faces, and which edges of ``adj`` they are.

    ``adj`` itself when every face is kept.
    """
    if keep.all():
        return adj, np.ones(len(adj.i), dtype=bool)
    both = keep[adj.i] & keep[adj.j]
    sides = None if adj.sides is None else (adj.sides[0][both], adj.sides[1][both])
    return FaceAdjacency(len(keep), adj.i[both], adj.j[both], sides=sides), both


def _search(
    centroids: F64,
    normals: F64,
    search: FaceAdjacency,
    within: npt.NDArray[np.bool_],
    p: SegmentParams,
) -> tuple[I32, npt.NDArray[np.bool_], npt.NDArray[np.bool_]]:
    """Run the paper's search (Eq. 2) over the edges of ``search`` from the faces ``within``.

    Returns:
        The per-face region ids (0 outside ``within``), and per edge of ``search`` whether Eq. 2
        passes from ``i`` to ``j`` and from ``j`` to ``i``.

    """
    m = len(within)
    towards_j, towards_i = edge_scores(centroids, normals, search.i, search.j)
    pass_ij, pass_ji = towards_j > p.threshold, towards_i > p.threshold
    if p.seed_order == 'index':
        seeds = np.flatnonzero(within)
    else:
        total = np.bincount(search.i, weights=towards_j, minlength=m) + np.bincount(
            search.j, weights=towards_i, minlength=m
        )
        count = search.neighbour_count()
        convexity = np.where(count > 0, total / np.maximum(count, 1), -np.inf)
        seeds = _most_convex_first(convexity, np.flatnonzero(within))
    return grow_regions(search.across_sides(pass_ij, pass_ji), seeds), pass_ij, pass_ji


def _no_step(name: str, labels: I32) -> None:
    """Take no note of a step."""


def segment_mesh(
    vertices: npt.ArrayLike,
    faces: npt.ArrayLike,
    params: SegmentParams | None = None,
    spec: Mapping[str, Any] | None = None,
    on_step: Callable[[str, I32], None] | None = None,
) -> Segmentation:
    """Segment a stockpile mesh (stockpile frame: z up, ground at ``z = 0``) into rocks.

    Open ground off the plane is found too where ``max_rock_b`` is known (see :mod:`.ground`).

    Args:
        vertices: Nx3 vertex positions.
        faces: Mx3 triangles, outward normals by the right-hand rule.
        params: Parameters; the ``default`` preset if None.
        spec: The class the gradation will be checked against, or None: when ``min_rock_b`` is
            0 it sets the smallest rock of interest (see ``rock_scale``).
        on_step: Called after each step that runs with its name (``STEPS``) and the per-face
            labels it left (not renumbered; read them, do not keep them), so that a bench can
            tell which step gains or loses a rock.

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
    normals = smooth_normals(geom, adj, p.normal_smoothing)
    active = np.ones(m, dtype=bool)
    tolerance = p.ground_tolerance_edges * edge
    ground = ground_height(geom.centroids, p.ground_window_b * scale.max_rock_b, edge, tolerance)
    if p.exclude_ground:
        level = np.nan_to_num(ground, nan=0.0)
        on_ground = geom.centroids[:, 2] - level < tolerance
        active &= ~(on_ground & (normals[:, 2] >= p.ground_min_nz))
    # One smoothing serves both scales: depths[0] is the valley's, depths[-1] the split's. A
    # mesh without a length (every edge degenerate) has no scale to look for valleys at.
    valley_radius, split_radius = scale.valley_radius, scale.split_radius
    scales = ((valley_radius, p.valley_depth_ratio), (split_radius, p.split_depth_ratio))
    radii = [r for r, d in scales if d > 0 and edge > 0]
    depths = valley_depths(v, f, geom, radii, edge, adj.vertex_edges) if radii else []
    valley = np.zeros(m, dtype=bool)
    if p.valley_depth_ratio > 0 and depths:
        valley = (depths[0] > p.valley_depth_ratio * valley_radius) & active
        active &= ~valley
    search, inner = _restricted(adj, active)
    labels, pass_ij, pass_ji = _search(geom.centroids, normals, search, active, p)
    passing = np.zeros(2 * len(adj.i), dtype=bool)
    passing[: len(adj.i)][inner] = pass_ij
    passing[len(adj.i) :][inner] = pass_ji
    step = on_step or _no_step
    step('search', labels)
    raw = int(labels.max()) if m else 0
    min_area = p.min_region_share * np.pi / 4.0 * scale.min_rock_b**2
    loose = np.zeros(m, dtype=bool)
    # Paper mode merges nothing and needs no degrees.
    degree = adj.neighbour_count() if min_area > 0 else None

    def merge(regions: I32, within: FaceAdjacency) -> I32:
        return merge_fragments(
            regions, within, geom.areas, min_area, p.merge_fragments, p.fragment_min_border, degree
        )

    if min_area > 0:
        searched = labels > 0
        labels = merge(labels, search)
        step('fragments', labels)
        loose = searched & (labels == 0)
        if p.neck_radii > 0:
            rings = math.ceil(RINGS_PER_EDGE * p.neck_radii * valley_radius / edge)
            labels = split_at_necks(labels, adj, geom.areas, rings, min_area)
            step('necks', labels)
    far = np.zeros(m, dtype=bool)
    if valley.any():
        if p.valley_reach > 0:
            # Downhill only: a rock's flank goes down to the valley's floor, and what rises beyond
            # it (the top of a rock sunk between others) is no flank of this region's rock.
            rings = math.ceil(RINGS_PER_EDGE * p.valley_reach * valley_radius / edge)
            down = depths[0][adj.dst] >= depths[0][adj.src]
            labels = hand_back(labels, adj, valley, rings, down)
            far = valley & (labels == 0)
            step('valleys near', labels)
        if p.far_valley_pieces and far.any():
            # The far valley faces cut by the search into pieces that join a rock only where
            # convex with it (as the fragments left out do): handed back whole, they carried
            # the sunk rocks round a partly buried one into its hull, and its own pieces were
            # then not convex together.
            within, _ = _restricted(adj, far)
            pieces, _, _ = _search(geom.centroids, normals, within, far, p)
            pieces = merge(pieces, within)
            labels = np.where(pieces > 0, pieces + labels.max(), labels).astype(np.int32)
            loose |= far
            step('far pieces', labels)
        else:
            # Every valley face, for the clean-ups to see regions that meet along the valleys'
            # middles; the far ones are left out again at the end.
            labels = hand_back(labels, adj, valley)
            step('valleys all', labels)
        search = adj
    if p.drop_facing_down:
        # After the valley faces are handed back: a region that reaches a rock across a valley
        # borders it and stays.
        labels = drop_facing_down(labels, adj, geom.areas * geom.normals[:, 2])
        step('undersides', labels)
    if p.hull_split and min_area > 0:
        # At the depth at which the convex join keeps a part of a fragment's area apart.
        depth = max(p.border_depth * math.sqrt(min_area), p.depth_min_edges * edge)
        labels = split_under_hulls(v, geom, labels, adj, f, depth, min_area, valley)
        step('hull split', labels)
    if p.merge_convex:
        if p.convex_fragments:
            # Each fragment the merge left out is a region again for the join, and left out
            # again unless joined: a piece of a larger rock, cut off by the search along noise,
            # is convex with it; a small rock wedged between larger ones is not.
            labels = label_parts(labels, adj, loose)
        labels = merge_convex_borders(
            v,
            geom,
            labels,
            search,
            f,
            p.border_depth,
            p.border_min_edges,
            p.depth_min_edges * edge,
        )
        if p.convex_fragments:
            labels = drop_unanchored(labels, loose)
        step('convex join', labels)
    if p.split_depth_ratio > 0 and depths:
        deep = depths[-1] > p.split_depth_ratio * split_radius
        labels = split_at_valleys(labels, adj, geom.areas, deep, p.split_min_share)
        step('valley split', labels)
    # The far valley faces are left out of every rock but those joined to one as pieces
    # (far_valley_pieces); handed back, they were there for the clean-ups alone.
    if far.any():
        if p.far_valley_pieces:
            labels = drop_unanchored(labels, far)
        else:
            labels = np.where(far, 0, labels).astype(np.int32)
        step('far valleys out', labels)
    return Segmentation(_renumber_by_size(labels), f, geom, adj, passing, raw, p, scale, ground)
