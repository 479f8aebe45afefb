"""The clean-ups after the search.

Faces handed back to their neighbours, fragments merged, regions split at necks and under their
hulls, undersides dropped, and neighbours joined where the border between them is convex.
"""

from __future__ import annotations

import contextlib
import heapq

import numpy as np
import numpy.typing as npt
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components
from scipy.spatial import ConvexHull, QhullError

from .adjacency import FaceAdjacency, FaceGeometry

__all__ = [
    'BORDER_SAMPLES',
    'HULL_SAMPLES',
    'drop_facing_down',
    'drop_unanchored',
    'hand_back',
    'label_parts',
    'merge_convex_borders',
    'merge_fragments',
    'region_bounds',
    'split_at_necks',
    'split_into_parts',
    'split_under_hulls',
]


F64 = npt.NDArray[np.float64]
I32 = npt.NDArray[np.int32]
I64 = npt.NDArray[np.int64]


BORDER_SAMPLES = 256


HULL_SAMPLES = 500

# Faces per block of the faces-by-facets products in ``split_under_hulls``.
HULL_CHUNK = 4096


def region_bounds(labels: I32) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """Faces in order of their label, and where each label's run starts.

    Returns:
        ``order`` and ``bounds``: the faces of label ``k`` are ``order[bounds[k] : bounds[k + 1]]``.

    """
    order = np.argsort(labels, kind='stable')
    return order, np.searchsorted(labels[order], np.arange(int(labels.max(initial=0)) + 2))


def hand_back(
    labels: I32,
    adj: FaceAdjacency,
    free: npt.NDArray[np.bool_],
    rings: int | None = None,
    along: npt.NDArray[np.bool_] | None = None,
) -> I32:
    """Give unlabelled ``free`` faces the label of a labelled neighbour, front by front.

    Every round each free face next to a labelled face takes its label, so a band between two
    regions is split where the fronts from both sides meet. With ``rings``, the fronts stop after
    that many rounds and the free faces they did not reach stay unlabelled; with ``along``, they
    only cross the directed edges ``adj.src -> adj.dst`` it marks.
    """
    labels = labels.copy()
    src, dst = adj.src, adj.dst
    open_edge = free[dst] & (labels[dst] == 0)
    if along is not None:
        open_edge &= along
    src, dst = src[open_edge], dst[open_edge]
    done = 0
    while rings is None or done < rings:
        take = labels[src] > 0
        if not take.any():
            break
        labels[dst[take]] = labels[src[take]]
        left = labels[dst] == 0
        src, dst = src[left], dst[left]
        done += 1
    return labels


def merge_fragments(
    labels: I32,
    adj: FaceAdjacency,
    areas: F64,
    min_area: float,
    merge: bool,
    min_border: float = 0.0,
    degree: npt.NDArray[np.int64] | None = None,
) -> I32:
    """Merge regions of less area than ``min_area`` into the neighbour they share most edges with.

    A fragment only moves into a neighbour that ranks higher by (area, id), so merges never cycle
    and the lowest-ranked fragment always moves: each round makes progress. Fragments with no
    labelled neighbour (all fragments when ``merge`` is off) get label 0, and so does a fragment
    whose best neighbour is a region (not a fragment) that it touches along less than
    ``min_border`` of its outline: a small rock wedged between larger ones reaches them through
    gaps in the valleys round it, and joined to one it would make a wrong rock of two. Two
    fragments join whatever their border (two pieces of one small rock may touch at a corner),
    and the union is judged again.

    Args:
        labels: Per-face region ids (0 = excluded).
        adj: Face adjacency.
        areas: Face areas.
        min_area: Regions under this area are fragments.
        merge: Whether fragments are merged (else they get label 0).
        min_border: Least share of a fragment's outline it must share with a region to join it.
        degree: Per face, its edge neighbours in the whole mesh (those left out of ``adj``, such
            as valley faces, count towards the outline); None: its neighbours in ``adj``.

    Returns:
        The labels, fragments merged or cleared.

    """
    labels = labels.copy()
    if min_area <= 0:
        return labels
    src, dst = adj.src, adj.dst
    if min_border > 0 and degree is None:
        degree = adj.neighbour_count()
    while True:
        sizes = np.bincount(labels, weights=areas, minlength=int(labels.max()) + 1)
        small = (sizes < min_area) & (np.bincount(labels, minlength=len(sizes)) > 0)
        small[0] = False
        if not small.any():
            return labels
        a = labels[src]
        # Regions only grow, so a later round's fragments are made of this round's: their edges
        # are all among these.
        near = small[a]
        src, dst, a = src[near], dst[near], a[near]
        b = labels[dst]
        cross = (a != b) & (b > 0)
        if not merge or not cross.any():
            labels[small[labels]] = 0
            return labels
        pair, count = np.unique(np.stack([a[cross], b[cross]], axis=1), axis=0, return_counts=True)
        order = np.lexsort((-count, pair[:, 0]))
        pair, count = pair[order], count[order]
        best = np.ones(len(pair), dtype=bool)
        best[1:] = pair[1:, 0] != pair[:-1, 0]
        frag, into, border = pair[best, 0], pair[best, 1], count[best]
        up = (sizes[into] > sizes[frag]) | ((sizes[into] == sizes[frag]) & (into > frag))
        target = np.arange(len(sizes))
        if degree is not None and min_border > 0:
            # The outline: edges to every face outside, those along the mesh's border aside.
            outline = np.bincount(labels, weights=degree, minlength=len(sizes))
            outline -= np.bincount(a[a == b], minlength=len(sizes))
            weak = ~small[into] & (border < min_border * outline[frag])
            # A fragment moving into one that leaves waits a round to find its new neighbour.
            gone = np.zeros(len(sizes), dtype=bool)
            gone[frag[weak]] = True
            up &= ~gone[into]
            into = np.where(weak, 0, into)
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


def _parts(
    adj: FaceAdjacency, faces: npt.NDArray[np.bool_], along: npt.NDArray[np.bool_]
) -> tuple[int, npt.NDArray[np.int64]]:
    """Find the connected parts of the ``faces`` over the edges ``along`` marks, in face order."""
    keep = along & faces[adj.i] & faces[adj.j]
    index = np.cumsum(faces) - 1
    count = int(faces.sum())
    # The graph of those faces alone: the parts are numbered by their first face either way.
    graph = sp.csr_matrix(
        (np.ones(int(keep.sum())), (index[adj.i[keep]], index[adj.j[keep]])), shape=(count, count)
    )
    n, part = connected_components(graph, directed=False)
    return int(n), np.asarray(part, dtype=np.int64)


def label_parts(labels: I32, adj: FaceAdjacency, free: npt.NDArray[np.bool_]) -> I32:
    """Give each connected part of the unlabelled ``free`` faces an id of its own.

    Returns:
        The labels, the parts numbered after every existing id.

    """
    free = free & (labels == 0)
    if not free.any():
        return labels
    _, part = _parts(adj, free, np.ones(len(adj.i), dtype=bool))
    out: I32 = labels.copy()
    out[free] = int(labels.max()) + 1 + part
    return out


def drop_unanchored(labels: I32, loose: npt.NDArray[np.bool_]) -> I32:
    """Give label 0 to every region all of whose faces are ``loose``."""
    anchored = np.bincount(labels, weights=(~loose).astype(np.float64)) > 0
    return np.where(anchored[labels], labels, 0).astype(np.int32)


RegionParts = tuple[npt.NDArray[np.bool_], I64, I64, I64, F64]


def _region_parts(
    labels: I32, adj: FaceAdjacency, areas: F64, solid: npt.NDArray[np.bool_]
) -> RegionParts:
    """Find the connected parts of each region's ``solid`` faces.

    Returns:
        Per edge of ``adj`` whether it lies inside a region; the solid faces; each one's part;
        each part's region and area.

    """
    same: npt.NDArray[np.bool_] = (labels[adj.i] == labels[adj.j]) & (labels[adj.i] > 0)
    solid = solid & (labels > 0)
    faces = np.flatnonzero(solid).astype(np.int64)
    if not len(faces):
        empty = np.zeros(0, dtype=np.int64)
        return same, faces, empty, empty, np.zeros(0)
    n, part = _parts(adj, solid, same)
    owner = np.zeros(n, dtype=np.int64)
    owner[part] = labels[faces]
    area = np.bincount(part, weights=areas[faces], minlength=n).astype(np.float64)
    return same, faces, part, owner, area


def split_into_parts(
    labels: I32, adj: FaceAdjacency, areas: F64, solid: npt.NDArray[np.bool_], least: F64
) -> I32:
    """Split each region whose ``solid`` faces fall into two or more large connected parts.

    Within a region, the solid faces fall into connected parts; where two or more of them hold
    at least ``least[region]`` area each, those become regions of their own and the rest of the
    region (what is not solid, and the small parts) goes, front by front within the region, to
    the part that reaches it first (see ``hand_back``). Other regions are left alone.

    Args:
        labels: Per-face region ids (0 = excluded).
        adj: Face adjacency.
        areas: Face areas.
        solid: Per face, whether it can hold a part together.
        least: Per region id, the least area of a part.

    Returns:
        The labels, each split region's parts numbered after every existing id.

    """
    return _split_parts(labels, adj, _region_parts(labels, adj, areas, solid), least)


def _split_parts(labels: I32, adj: FaceAdjacency, parts: RegionParts, least: F64) -> I32:
    """Split each region with two or more of ``parts`` of ``least`` area (``split_into_parts``)."""
    m = len(labels)
    same, faces, part, owner, part_area = parts
    if not len(faces):
        return labels
    n = len(owner)
    big = part_area >= least[owner]
    split = np.bincount(owner[big], minlength=len(least)) >= 2
    split[0] = False
    if not split.any():
        return labels
    out = np.where(split[labels], 0, labels).astype(np.int32)
    kept = big & split[owner]
    ids = np.zeros(n, dtype=np.int32)
    ids[kept] = int(labels.max()) + 1 + np.arange(int(kept.sum()), dtype=np.int32)
    seeded = kept[part]
    out[faces[seeded]] = ids[part[seeded]]
    return hand_back(out, FaceAdjacency(m, adj.i[same], adj.j[same]), split[labels])


def split_at_necks(labels: I32, adj: FaceAdjacency, areas: F64, rings: int, min_core: float) -> I32:
    """Split each region that a neck joins: parts wider than ``2 rings`` linked by a narrow pass.

    Each region is eroded by ``rings`` rings of faces from its outline (its edges to every other
    label, 0 included, and the mesh's border); where what is left (its cores) falls into two or
    more parts of at least ``min_core`` area each, the region is split into them (see
    ``split_into_parts``).

    Args:
        labels: Per-face region ids (0 = excluded).
        adj: Face adjacency of the whole mesh (faces left out of the search count as outline).
        areas: Face areas.
        rings: Depth of the erosion, in rings of faces.
        min_core: Least area of a core that makes a part.

    Returns:
        The labels, each split region's parts numbered after every existing id.

    """
    i, j = adj.i, adj.j
    li = labels[i]
    inner = (li == labels[j]) & (li > 0)
    # The outline (a face with an edge out of its region or on the mesh's border) is ring 0;
    # unlabelled faces and regions too small to hold two cores are left out from the start.
    area = np.bincount(labels, weights=areas)
    reached = labels == 0
    reached[i[~inner]] = True
    reached[j[~inner]] = True
    reached |= adj.neighbour_count() < 3
    reached |= (area < 2 * min_core)[labels]
    i, j = i[inner], j[inner]
    for _ in range(rings):
        ri, rj = reached[i], reached[j]
        # Both ends of an edge with an end reached are reached after this ring: it is done.
        reached[j[ri]] = True
        reached[i[rj]] = True
        far = ~(ri | rj)
        i, j = i[far], j[far]
    core = ~reached
    # A region whose cores together are under two parts' area cannot split.
    room = np.bincount(labels[core], weights=areas[core], minlength=len(area))
    core &= (room >= 2 * min_core)[labels]
    return split_into_parts(labels, adj, areas, core, np.full(len(area), min_core))


def _under_hull(points: F64, eq: F64, depth: float) -> npt.NDArray[np.bool_]:
    """Whether each point lies deeper than ``depth`` under every facet plane of ``eq``."""
    height: F64 = (points @ eq[:, :3].T + eq[:, 3]).max(axis=1)
    return height < -depth


def split_under_hulls(
    vertices: F64,
    geom: FaceGeometry,
    labels: I32,
    adj: FaceAdjacency,
    faces: npt.NDArray[np.int64],
    max_depth: float,
    min_part: float,
    outside: npt.NDArray[np.bool_],
) -> I32:
    """Split each region that a band of faces deep under its own convex hull cuts into parts.

    One convex rock's surface lies on its hull; where two touching rocks share a region, the
    crease between them lies under the hull of the pair. Each region of at least ``min_part``
    area is taken apart at its faces deeper than ``max_depth`` under the hull of its vertices
    (the distance to the nearest facet's plane); where the rest falls into two or more parts of
    at least ``min_part`` area each, those become regions (see ``split_into_parts``). Where no
    part is that large, the region is several rocks smaller than the smallest of interest taken
    for one (fines under it, or the slivers of buried rocks) and gets label 0: parts that small
    are not rocks to report, and together they are no rock at all. The hull is that of
    the corners of an even stride of its faces, and a region is looked into where one of an even
    stride of ``BORDER_SAMPLES`` of its faces is that deep (a band that cuts a region is many
    faces long).

    Args:
        vertices: Nx3 vertex positions.
        geom: Face centroids and areas.
        labels: Per-face region ids (0 = excluded).
        adj: Face adjacency.
        faces: Mx3 triangles.
        max_depth: Depth under the hull beyond which a face holds no part together [m].
        min_part: Least area of a part.
        outside: Faces that neither shape a region's hull nor hold a part together (valley
            faces handed back to the regions).

    Returns:
        The labels, each split region's parts numbered after every existing id and each region
        of small parts alone cleared.

    """
    area = np.bincount(labels, weights=geom.areas)
    solid = ~outside
    cut = np.zeros(len(area), dtype=bool)
    order, bounds = region_bounds(labels)
    for region in np.flatnonzero(area[1:] >= min_part) + 1:
        idx = order[bounds[region] : bounds[region + 1]]
        idx = idx[solid[idx]]
        if not len(idx):
            continue
        # The corners of an even stride of its faces, about ``HULL_SAMPLES`` points: a hull
        # within a fraction of an edge of the whole one (see ``_hull_points``).
        corners = vertices[faces[idx[:: -(-3 * len(idx) // HULL_SAMPLES)]].ravel()]
        try:
            eq = ConvexHull(corners).equations
        except (QhullError, ValueError):
            continue
        # A strided sample of the faces first: where none of them is deep, the region is one
        # convex rock and the faces-by-facets products of the whole region are not needed.
        sample = idx[:: -(-len(idx) // BORDER_SAMPLES)]
        if _under_hull(geom.centroids[sample], eq, max_depth).any():
            cut[region] = True
            for start in range(0, len(idx), HULL_CHUNK):
                part = idx[start : start + HULL_CHUNK]
                solid[part] = ~_under_hull(geom.centroids[part], eq, max_depth)
    if not cut.any():
        return labels
    # Only the regions with a deep band hold solid faces to part: the others are left as they are.
    parts = _region_parts(labels, adj, geom.areas, solid & cut[labels])
    owner, part_area = parts[3], parts[4]
    largest = np.zeros(len(area))
    np.maximum.at(largest, owner, part_area)
    small = cut & (largest < min_part)
    small[0] = False
    # The parts stay as found: a cleared region holds none of ``min_part``, so none splits.
    labels = np.where(small[labels], 0, labels).astype(np.int32)
    return _split_parts(labels, adj, parts, np.full(len(area), min_part))


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
    sample of its vertices is returned. On a rounded rock of radius R, 500 samples put the hull
    within about 0.003 R of the full one, against a join threshold near 0.2 R (``border_depth``
    of the square root of the area).
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


def _pair(a: int, b: int) -> tuple[int, int]:
    return (a, b) if a < b else (b, a)


def merge_convex_borders(
    vertices: F64,
    geom: FaceGeometry,
    labels: I32,
    adj: FaceAdjacency,
    faces: npt.NDArray[np.int64],
    max_depth: float,
    min_edges: int,
    min_depth: float = 0.0,
) -> I32:
    """Join neighbouring regions whose union is convex across their shared border.

    The shared border of two parts of one convex rock lies on the convex hull of their union; the
    valley where two rocks touch lies under it. The test is the median depth of the border
    (midpoints of the centroids of the face pairs across it) under the hull of the union's
    vertices, measured along the border's outward normal, over the square root of the smaller
    region's area; the shallowest border is joined first, and after each join the borders of the
    joined region are judged again (the others keep their depth).

    Args:
        vertices: Nx3 vertex positions.
        geom: Face centroids and areas.
        labels: Per-face region ids (0 = excluded).
        adj: Face adjacency.
        faces: Mx3 triangles.
        max_depth: Borders with a relative depth under this are joined.
        min_edges: Borders of fewer face edges are left alone.
        min_depth: Least depth taken as a crease [m]: a border shallower is joined whatever
            the regions' size (the square root of the smaller area is taken as at least
            ``min_depth / max_depth``).

    Returns:
        The merged labels (ids are those of the surviving regions).

    """
    # Each region's hull vertices, found once: the hull of a union is the hull of theirs.
    order, bounds = region_bounds(labels)
    hulls: dict[int, F64] = {}
    used = np.zeros(len(vertices), dtype=bool)

    def hull_of(region: int) -> F64:
        if region not in hulls:
            # The region's vertices in index order: a large region's through a mask of every
            # vertex (no sort), a small one's sorted (a pass over every vertex would cost more).
            tri = faces[order[bounds[region] : bounds[region + 1]]]
            if tri.size * 8 < len(used):
                ids = np.unique(tri)
            else:
                used[tri] = True
                ids = np.flatnonzero(used)
                used[ids] = False
            hulls[region] = _hull_points(vertices[ids])
        return hulls[region]

    # The faces either side of every border between two regions, found once: a join only turns
    # borders into insides and two borders into one, so each pair of regions keeps the indices
    # of its border's edges (in mesh order, which the strided sample of a border follows).
    a, b = labels[adj.i], labels[adj.j]
    edges = np.flatnonzero((a != b) & (a > 0) & (b > 0))
    fi, fj = adj.i[edges], adj.j[edges]
    mid = 0.5 * (geom.centroids[fi] + geom.centroids[fj])
    out = geom.normals[fi] + geom.normals[fj]
    out /= np.maximum(np.linalg.norm(out, axis=1, keepdims=True), 1e-12)
    area = np.bincount(labels, weights=geom.areas)
    lo, hi = np.minimum(a[edges], b[edges]), np.maximum(a[edges], b[edges])
    key = lo.astype(np.int64) * (int(labels.max()) + 1) + hi
    by_key = np.argsort(key, kind='stable')
    split = np.flatnonzero(np.diff(key[by_key])) + 1
    border: dict[tuple[int, int], npt.NDArray[np.int64]] = {
        (int(lo[run[0]]), int(hi[run[0]])): run for run in np.split(by_key, split) if len(run)
    }
    near: dict[int, set[int]] = {}
    for r, q in border:
        near.setdefault(r, set()).add(q)
        near.setdefault(q, set()).add(r)
    floor = min_depth / max_depth if max_depth > 0 else 0.0
    # The shallowest border first, ties to the lowest pair; a pair's depth is found again when
    # either region grows, and a queued depth that is no longer the pair's is passed over.
    queue: list[tuple[float, tuple[int, int]]] = []
    depth: dict[tuple[int, int], float] = {}

    def judge(pair: tuple[int, int]) -> None:
        sel = border[pair]
        if len(sel) < min_edges:
            depth.pop(pair, None)
            return
        size = max(float(np.sqrt(min(area[pair[0]], area[pair[1]]))), floor)
        union = np.concatenate([hull_of(pair[0]), hull_of(pair[1])])
        depth[pair] = _border_depth(union, mid[sel], out[sel], size)
        if depth[pair] < max_depth:
            heapq.heappush(queue, (depth[pair], pair))

    for pair in border:
        judge(pair)
    into = np.arange(len(area))
    while queue:
        d, pair = heapq.heappop(queue)
        if depth.get(pair) != d:
            continue
        keep, gone = pair
        hulls[keep] = _hull_points(np.concatenate([hull_of(keep), hull_of(gone)]))
        area[keep] += area[gone]
        into[gone] = keep
        del border[pair], depth[pair]
        near[keep].discard(gone)
        for r in near.pop(gone) - {keep}:
            old, grown = _pair(r, gone), _pair(r, keep)
            moved, kept = border.pop(old), border.get(grown)
            depth.pop(old, None)
            near[r].discard(gone)
            near[r].add(keep)
            near[keep].add(r)
            border[grown] = moved if kept is None else np.sort(np.concatenate([kept, moved]))
        for r in near[keep]:
            judge(_pair(r, keep))
    # Each joined region to the region it ended in: ids only ever join smaller ids.
    while True:
        nxt = into[into]
        if np.array_equal(nxt, into):
            break
        into = nxt
    return into[labels].astype(np.int32)
