"""Rules that scale: every length of the default mode is in edge lengths or in the smallest rock."""

from __future__ import annotations

import re
from dataclasses import replace

import numpy as np
import numpy.typing as npt
import pytest
from segment_fixtures import boulders_on, height_field, small_pile

from stockpile_ros.artefacts import MeshInfo, ScaleRecord
from stockpile_ros.segment.adjacency import FaceAdjacency
from stockpile_ros.segment.cleanup import drop_facing_down, merge_fragments
from stockpile_ros.segment.gradation import load_class_table
from stockpile_ros.segment.measure import MeasureParams, measure_rocks
from stockpile_ros.segment.params import (
    RESOLVABLE_EDGES,
    SHARP_EDGES,
    SegmentParams,
    class_max_rock_b,
    class_min_rock_b,
    median_edge,
    rock_scale,
)
from stockpile_ros.segment.pipeline import TRUNCATED_MIN_ROCKS, analyse_mesh, truncation_warnings
from stockpile_ros.segment.segmentation import segment_mesh

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]


def _subdivide(v: F64, f: I64) -> tuple[F64, I64, I64]:
    """Split every triangle into four at its edge midpoints, shared by the faces on both sides.

    Returns:
        Vertices, faces and the parent face of each new face.

    """
    a, b, c = f[:, 0], f[:, 1], f[:, 2]
    edges = np.stack([np.stack([a, b], 1), np.stack([b, c], 1), np.stack([c, a], 1)], axis=1)
    key = np.sort(edges.reshape(-1, 2), axis=1)
    uniq, inv = np.unique(key, axis=0, return_inverse=True)
    mid = len(v) + inv.reshape(-1, 3)
    verts = np.concatenate([v, 0.5 * (v[uniq[:, 0]] + v[uniq[:, 1]])])
    ab, bc, ca = mid[:, 0], mid[:, 1], mid[:, 2]
    faces = np.concatenate(
        [np.stack(t, 1) for t in ((a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca))]
    )
    return verts, faces, np.tile(np.arange(len(f)), 4)


def _agreement(labels: npt.NDArray[np.int32], other: npt.NDArray[np.int32], w: F64) -> float:
    """Share of the area where ``other`` agrees with ``labels`` after each label of ``labels`` is
    matched to the label of ``other`` it overlaps most."""
    n = int(other.max()) + 1
    agree = 0.0
    for k in np.unique(labels):
        sel = labels == k
        agree += float(np.bincount(other[sel], weights=w[sel], minlength=n).max())
    return agree / float(w.sum())


@pytest.mark.parametrize('factor', [0.1, 10.0])
def test_a_scaled_pile_segments_and_measures_the_same(factor: float) -> None:
    v, f, _ = small_pile()
    base = segment_mesh(v, f)
    scaled = segment_mesh(v * factor, f)
    assert base.labels.max() >= 3
    assert scaled.scale.edge == pytest.approx(factor * base.scale.edge, rel=1e-9)
    # Labels are numbered by size, so equal segmentations have equal labels.
    np.testing.assert_array_equal(scaled.labels, base.labels)
    rocks, big = measure_rocks(v, base), measure_rocks(v * factor, scaled)
    assert [r.id for r in big] == [r.id for r in rocks]
    for r, s in zip(rocks, big, strict=True):
        assert s.b == pytest.approx(factor * r.b, rel=1e-6)
        assert s.mass == pytest.approx(factor**3 * r.mass, rel=1e-6)


def test_a_subdivided_pile_segments_the_same_given_the_smallest_rock() -> None:
    # Subdivision halves the median edge: the rock of interest is given in metres, and so the
    # fragment area and the valley scales stay where they were.
    v, f, _ = small_pile()
    base = segment_mesh(v, f)
    params = SegmentParams(min_rock_b=base.scale.min_rock_b)
    v2, f2, parent = _subdivide(v, f)
    fine = segment_mesh(v2, f2, params)
    assert fine.scale.edge == pytest.approx(0.5 * base.scale.edge, rel=0.1)
    assert fine.labels.max() == base.labels.max()
    assert _agreement(base.labels[parent], fine.labels, fine.geometry.areas) > 0.97
    rocks = {r.id: r for r in measure_rocks(v, base)}
    for fine_rock in measure_rocks(v2, fine):
        sel = fine.labels == fine_rock.id
        overlap = np.bincount(base.labels[parent][sel], weights=fine.geometry.areas[sel])
        match = int(overlap.argmax())
        assert fine_rock.b == pytest.approx(rocks[match].b, rel=0.03)


def _bumps(n: int, per: int) -> tuple[F64, I64]:
    """``n`` x ``n`` touching spherical caps 1 m apart, ``per`` grid cells across each."""

    def z(x: F64, y: F64) -> F64:
        # A sphere of radius 0.6 m on each 1 m cell: neighbours meet in a crease at 0.33 m, the
        # ground shows at the corners.
        d2 = (x - np.floor(x) - 0.5) ** 2 + (y - np.floor(y) - 0.5) ** 2
        return np.asarray(np.sqrt(np.maximum(0.36 - d2, 0.0)))

    v, f = height_field(z, n / 2, n * per + 1)
    v[:, :2] += n / 2
    return v, f


def test_hundreds_of_rocks_are_not_fragments_of_the_pile() -> None:
    # 144 rocks, each under 1 % of the surface: a rule relative to the pile (regions under 1 % of
    # the faces merged away) joined most of them; the smallest rock of interest does not.
    v, f = _bumps(12, 32)
    seg = segment_mesh(v, f)
    assert seg.scale.source == 'mesh'
    centres = np.stack(np.meshgrid(np.arange(12) + 0.5, np.arange(12) + 0.5), -1).reshape(-1, 2)
    xy = seg.geometry.centroids[:, :2]
    tops = [int(np.argmin(np.linalg.norm(xy - c, axis=1))) for c in centres]
    assert len(set(seg.labels[tops].tolist())) == 144
    assert seg.labels.max() == 144


def test_the_smallest_rock_comes_from_the_parameter_the_class_or_the_mesh() -> None:
    params = SegmentParams()
    mesh = rock_scale(params, 0.001)
    assert (mesh.source, mesh.min_rock_b) == ('mesh', pytest.approx(params.min_rock_edges * 0.001))
    spec = load_class_table()['classes']['I']
    # Class I: D15 at least 3.7 in; half of it, on a mesh fine enough to resolve it.
    assert class_min_rock_b(spec) == pytest.approx(0.5 * 3.7 * 0.0254)
    from_class = rock_scale(params, 0.001, spec)
    assert (from_class.source, from_class.min_rock_b) == ('class', pytest.approx(0.047, abs=1e-3))
    assert from_class.requested == from_class.min_rock_b
    given = rock_scale(replace(params, min_rock_b=0.3), 0.001, spec)
    assert (given.source, given.min_rock_b) == ('parameter', 0.3)
    # The largest rock: the parameter, else the class's largest upper limit (D100 at most 12 in).
    assert class_max_rock_b(spec) == pytest.approx(12 * 0.0254)
    assert from_class.max_rock_b == pytest.approx(12 * 0.0254)
    assert rock_scale(replace(params, max_rock_b=0.5), 0.001, spec).max_rock_b == 0.5
    assert mesh.max_rock_b == 0.0


def test_no_scale_goes_under_what_the_mesh_resolves() -> None:
    params = SegmentParams()
    spec = load_class_table()['classes']['I']
    # Class I's 47 mm on a mesh of 4 mm edges: under min_rock_edges, raised to it, and recorded.
    coarse = rock_scale(params, 0.004, spec)
    assert coarse.source == 'class'
    assert coarse.requested == pytest.approx(0.047, abs=1e-3)
    assert coarse.min_rock_b == pytest.approx(params.min_rock_edges * 0.004)
    tiny = rock_scale(replace(params, min_rock_b=1e-4, min_rock_edges=RESOLVABLE_EDGES), 0.004)
    assert tiny.min_rock_b == pytest.approx(RESOLVABLE_EDGES * 0.004)
    # The radii keep their share of a large rock of interest, and their floor in edges under it.
    large = rock_scale(replace(params, min_rock_b=1.0), 0.004)
    assert large.valley_radius == pytest.approx(params.valley_radius_b * 1.0)
    assert large.split_radius == pytest.approx(params.split_radius_b * 1.0)
    assert coarse.valley_radius == pytest.approx(params.valley_min_edges * 0.004)
    assert coarse.split_radius == pytest.approx(params.split_min_edges * 0.004)


def test_a_class_finer_than_the_mesh_is_warned_about() -> None:
    v, f = _bumps(3, 32)
    spec = load_class_table()['classes']['I']
    # Median edges of about 43 mm: class I's 47 mm is about one of them. The class sizes the
    # segmentation only on a metric mesh.
    metric = MeshInfo(ScaleRecord('target', 1.0, 0.01), units='m')
    warned = analyse_mesh(v, f, spec=spec, mesh_info=metric).report.warnings
    assert any('the mesh resolves' in w for w in warned)
    assert not any('the mesh resolves' in w for w in analyse_mesh(v, f).report.warnings)


def test_a_rock_of_interest_under_sharp_edges_is_warned_about() -> None:
    v, f = _bumps(3, 32)
    edge = median_edge(v, f)
    metric = MeshInfo(ScaleRecord('target', 1.0, 0.01), units='m')

    def warned(edges: float) -> bool:
        params = SegmentParams(min_rock_b=edges * edge)
        report = analyse_mesh(v, f, seg_params=params, mesh_info=metric).report
        return any('to edges of' in w for w in report.warnings)

    # Resolved (over min_rock_edges) but under SHARP_EDGES: warned; at or over it, or with no
    # rock of interest asked for, not.
    assert warned(0.8 * SHARP_EDGES)
    assert not warned(1.1 * SHARP_EDGES)
    assert not any('to edges of' in w for w in analyse_mesh(v, f).report.warnings)


def test_sizes_cut_by_the_mesh_floor_are_warned_about() -> None:
    # Rocks spread evenly by mass in log size between lo and 4 b0: eight times more rocks for
    # each halving of b. Cut by the floor (lo under b0) the band just above it is the fullest.
    b0 = 0.1
    scale = rock_scale(SegmentParams(), b0 / SegmentParams().min_rock_edges)

    def sizes(lo: float) -> list[float]:
        edges = np.geomspace(lo, 4 * b0, 9)
        counts = np.round(400 * (edges[0] / edges[:-1]) ** 3).astype(int)
        b = np.concatenate(
            [
                np.full(n, np.sqrt(x * y))
                for n, x, y in zip(counts, edges[:-1], edges[1:], strict=True)
            ]
        )
        return [float(x) for x in b if x >= b0]

    (text,) = truncation_warnings(scale, sizes(0.5 * b0), 'm')
    assert 'do not fall off towards 0.1 m' in text and '(20 median edge lengths)' in text
    assert truncation_warnings(scale, sizes(1.6 * b0), 'm') == []
    # Pieces of larger rocks just above the floor are fewer than the rocks of the fullest band.
    pieces = [1.1 * b0] * TRUNCATED_MIN_ROCKS
    assert truncation_warnings(scale, pieces + sizes(1.6 * b0), 'm') == []
    assert truncation_warnings(scale, pieces + [1.9 * b0] * 3, 'm') == []
    assert truncation_warnings(scale, pieces + [1.9 * b0] * 2, 'm')
    # Too few to tell, or a smallest rock given: the floor is what was asked for.
    assert truncation_warnings(scale, [1.1 * b0] * (TRUNCATED_MIN_ROCKS - 1), 'm') == []
    given = rock_scale(SegmentParams(min_rock_b=b0), scale.edge)
    assert truncation_warnings(given, sizes(0.5 * b0), 'm') == []
    # Through the pipeline: 36 rocks of b 1.17 on a mesh resolving 0.85 warn, on one resolving
    # 0.43 do not.
    assert any('do not fall off' in w for w in analyse_mesh(*_bumps(6, 32)).report.warnings)
    assert not any('do not fall off' in w for w in analyse_mesh(*_bumps(6, 64)).report.warnings)


def test_a_group_of_sizes_near_the_floor_apart_from_the_rest_is_warned_about() -> None:
    b0 = 0.1
    scale = rock_scale(SegmentParams(), b0 / SegmentParams().min_rock_edges)

    def sizes(*counts: int) -> list[float]:
        # counts[k] rocks in the k-th band of a factor sqrt 2 from b0 up, at its middle.
        return [b0 * 2 ** ((k + 0.5) / 2) for k, n in enumerate(counts) for _ in range(n)]

    # bench/bench_cloud.py's riprap bed scanned at 7 mm: pieces near the floor, a gap, the rocks.
    (text,) = truncation_warnings(scale, sizes(36, 29, 11, 20, 45, 12, 5), 'm')
    assert text.startswith('The sizes come in two groups: 65 of 158 rocks measure b under 0.2 m')
    assert 'and 82 from 0.283 m up, with 11 between (36 and 45 in the fullest band' in text
    assert '(segment.min_rock_b: 0.283 m, where the larger group begins' in text
    # A pile falling off from the floor, or rising from it to its own smallest rocks: one group.
    assert truncation_warnings(scale, sizes(30, 25, 20, 12, 6, 2), 'm') == []
    assert truncation_warnings(scale, sizes(39, 107, 46, 11, 4), 'm') == []
    # A gap within the draw of its neighbours' counts, or groups too small to tell, is none.
    assert truncation_warnings(scale, sizes(36, 29, 30, 28, 45, 12, 5), 'm') == []
    assert truncation_warnings(scale, sizes(9, 3, 0, 9, 20), 'm') == []
    assert truncation_warnings(scale, sizes(12, 3, 0, 10, 20), 'm')
    # A group apart from the floor says nothing of it: a pile of two sizes well above it.
    assert truncation_warnings(scale, sizes(0, 0, 0, 30, 5, 40), 'm') == []
    # A smallest rock given is what was asked for.
    given = rock_scale(SegmentParams(min_rock_b=b0), scale.edge)
    assert truncation_warnings(given, sizes(36, 29, 11, 20, 45, 12, 5), 'm') == []


def test_fragments_are_judged_by_area_not_by_face_count() -> None:
    # A strip of 10 faces: region 1 is 6 small faces (area 0.6), region 2 is 4 large ones (4.0).
    adj = FaceAdjacency(10, np.arange(9), np.arange(1, 10))
    labels = np.array([1] * 6 + [2] * 4, dtype=np.int32)
    areas = np.array([0.1] * 6 + [1.0] * 4)
    assert merge_fragments(labels, adj, areas, 1.0, True).tolist() == [2] * 10
    assert merge_fragments(labels, adj, areas, 0.5, True).tolist() == labels.tolist()
    assert merge_fragments(labels, adj, areas, 1.0, False).tolist() == [0] * 6 + [2] * 4


def test_median_edge_leaves_degenerate_edges_out() -> None:
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 0]], dtype=np.float64)
    # The second face has two zero-length edges (vertices 0 and 3 coincide).
    f = np.array([[0, 1, 2], [0, 3, 1]])
    assert median_edge(v, f) == pytest.approx(1.0)
    assert median_edge(np.zeros((3, 3)), np.array([[0, 1, 2]])) == 0.0


def test_a_lone_region_facing_down_is_dropped() -> None:
    # 1 1 1 2 2 | 3 3: regions 2 and 3 face down; 2 borders region 1, 3 borders nothing.
    adj = FaceAdjacency(7, np.array([0, 1, 2, 3, 5]), np.array([1, 2, 3, 4, 6]))
    labels = np.array([1, 1, 1, 2, 2, 3, 3], dtype=np.int32)
    lift = np.array([1.0, 1.0, 1.0, -1.0, 0.5, -1.0, -1.0])
    assert drop_facing_down(labels, adj, lift).tolist() == [1, 1, 1, 2, 2, 0, 0]
    assert drop_facing_down(labels, adj, np.abs(lift)).tolist() == labels.tolist()


def test_ground_off_the_plane_is_left_out_as_a_sheet_with_a_warning() -> None:
    # Nine boulders on ground waving 3 cm over a 1.2 m period: the crests stand above the
    # ground tolerance of z = 0 and grow regions metres wide and a few centimetres thick.
    centres = [(x, y) for x in (-0.8, 0.0, 0.8) for y in (-0.8, 0.0, 0.8)]

    def ground(x: F64, y: F64) -> F64:
        return np.asarray(0.03 * (np.sin(2 * np.pi * x / 1.3) * np.cos(2 * np.pi * y / 1.1) + 1))

    v, f = boulders_on(ground, centres)
    info = MeshInfo(ScaleRecord('given', 1.0), units='m')
    kept = analyse_mesh(v, f, mesh_info=info, measure_params=MeasureParams(min_thickness=0.0))
    assert max(r.b for r in kept.rocks) > 1.0  # the crests, measured as a rock
    analysis = analyse_mesh(v, f, mesh_info=info)
    assert len(analysis.rocks) == len(centres) and all(r.b < 0.5 for r in analysis.rocks)
    said = [re.match(r'(\d+) regions? left out as sheets', w) for w in analysis.report.warnings]
    counts = [int(m.group(1)) for m in said if m]
    sheets = set(np.unique(kept.segmentation.labels)) - set(np.unique(analysis.segmentation.labels))
    # Their faces are no rock's in the segmented mesh either, and the warning counts them.
    assert counts == [len(sheets)] and len(sheets) >= 1


def test_most_convex_first_is_a_stable_sort() -> None:
    from stockpile_ros.segment.segmentation import _most_convex_first

    rng = np.random.default_rng(3)
    for trial in range(60):
        n = int(rng.integers(1, 3000))
        c = 1 + rng.integers(0, 3, size=n) * 1e-13 if trial % 2 else rng.normal(size=n).round(2)
        c[rng.random(n) < 0.05] = -np.inf
        c[rng.random(n) < 0.05] = -0.0
        faces = np.flatnonzero(rng.random(n) < 0.7)
        want = faces[np.argsort(-c[faces], kind='stable')]
        assert np.array_equal(_most_convex_first(c, faces), want)


def test_a_fragment_joins_a_region_only_along_a_share_of_its_outline() -> None:
    # Faces 0-2 a fragment (area 0.3) touching region 2 (faces 3-6) along one edge; in the whole
    # mesh every face has three neighbours, so the fragment's outline is 9 - 4 = 5 edges.
    adj = FaceAdjacency(7, np.arange(6), np.arange(1, 7))
    labels = np.array([1] * 3 + [2] * 4, dtype=np.int32)
    areas = np.array([0.1] * 3 + [1.0] * 4)
    degree = np.full(7, 3)
    assert merge_fragments(labels, adj, areas, 1.0, True, 0.2, degree).tolist() == [2] * 7
    dropped = [0] * 3 + [2] * 4
    assert merge_fragments(labels, adj, areas, 1.0, True, 0.25, degree).tolist() == dropped
    # Within the adjacency alone the outline is that one edge: it joins.
    assert merge_fragments(labels, adj, areas, 1.0, True, 0.25).tolist() == [2] * 7


def test_two_fragments_join_whatever_their_border() -> None:
    # Two fragments of 0.6 each touching along one edge of their outlines of 4: together a region.
    adj = FaceAdjacency(4, np.arange(3), np.arange(1, 4))
    labels = np.array([1, 1, 2, 2], dtype=np.int32)
    areas = np.full(4, 0.3)
    merged = merge_fragments(labels, adj, areas, 1.0, True, 0.5, np.full(4, 3))
    assert merged.tolist() == [2] * 4
