"""The field-like yardstick: a bed of a hundred rocks covering the ground, segmented and scored."""

from __future__ import annotations

import functools

import numpy as np
import pytest

from stockpile_ros.cloud.mesh import estimate_normals
from stockpile_ros.errors import StockpileError
from stockpile_ros.segment.measure import measure_rocks
from stockpile_ros.segment.params import SegmentParams
from stockpile_ros.segment.segmentation import STEPS, segment_mesh
from stockpile_ros.tools.evaluation.labels import (
    LabelScore,
    SizedRock,
    label_outcomes,
    score_labels,
)
from stockpile_ros.tools.sim.bed import (
    BedConfig,
    BedSurface,
    bed_surface,
    build_bed,
    drape,
)
from stockpile_ros.tools.sim.pile import Gradation, PlacedRock

SMALLEST = 0.1


@functools.lru_cache(maxsize=1)
def _bed() -> list[PlacedRock]:
    cfg = BedConfig(rocks=110, gradation=Gradation((SMALLEST, 0.3), (0.0, 100.0)), subdivisions=2)
    return build_bed(np.random.default_rng(2), cfg)


@functools.lru_cache(maxsize=2)
def _surface(edges: float) -> BedSurface:
    return bed_surface(_bed(), SMALLEST / edges, np.random.default_rng(2), noise_cells=0.2)


def _truth(surface: BedSurface) -> dict[int, SizedRock]:
    return {
        k: SizedRock(r['b'], r['mass'], r['visible_fraction']) for k, r in surface.rocks.items()
    }


def test_the_bed_covers_the_ground_and_hides_some_rocks() -> None:
    surface = _surface(8.0)
    centres = surface.vertices[surface.faces].mean(axis=1)
    rocks = np.concatenate([r.mesh.vertices for r in _bed()])
    # Inside the square the rocks fell on (half the bed's width round its middle), no ground.
    middle = 0.25 * (rocks[:, :2].max(axis=0) - rocks[:, :2].min(axis=0))
    inner = np.all(np.abs(centres[:, :2] - rocks[:, :2].mean(axis=0)) < middle, axis=1)
    areas = np.linalg.norm(
        np.cross(
            surface.vertices[surface.faces[:, 1]] - surface.vertices[surface.faces[:, 0]],
            surface.vertices[surface.faces[:, 2]] - surface.vertices[surface.faces[:, 0]],
        ),
        axis=1,
    )
    assert areas[inner & (surface.labels == 0)].sum() < 0.05 * areas[inner].sum()
    seen = np.array([r['visible_fraction'] for r in surface.rocks.values()])
    assert np.all((seen >= 0) & (seen <= 1))
    # Stacked more than one layer deep: many rocks are mostly hidden, many mostly seen.
    assert 0.2 < np.mean(seen < 0.3) < 0.6
    assert np.mean(seen >= 0.3) > 0.4
    assert {r.shape for r in _bed()} == {'equant', 'flat', 'elongated'}


def test_what_was_seen_does_not_depend_on_the_mesh() -> None:
    # The truth is surveyed at a spacing of the smallest rock, whatever the Poisson cell.
    fine, coarse = _surface(8.0), bed_surface(_bed(), SMALLEST / 4, np.random.default_rng(2))
    assert len(coarse.faces) < 0.5 * len(fine.faces)
    for k, rock in fine.rocks.items():
        assert coarse.rocks[k]['visible_fraction'] == rock['visible_fraction']


def test_perfect_labels_score_perfectly_and_a_merge_does_not() -> None:
    truth = {1: SizedRock(1.0, 1.0, 0.8), 2: SizedRock(2.0, 8.0, 0.8), 3: SizedRock(1.0, 1.0, 0.1)}
    true_labels = np.array([1, 1, 2, 2, 2, 3, 0])
    areas = np.ones(7)
    same = score_labels(true_labels, true_labels, areas, truth, truth)
    assert (same.visible, same.found, same.recall, same.precision) == (2, 2, 1.0, 1.0)
    assert same.b_error == 0.0
    assert sorted(same.pairs) == [(1, 1), (2, 2), (3, 3)]
    # Rock 3 is barely visible: its match counts neither way, and nor would its pieces.
    assert same.reported == 3
    halves, pieces = np.array([1, 1, 2, 2, 2, 3, 3, 0]), np.array([1, 1, 2, 2, 2, 3, 4, 0])
    measured = {**truth, 4: SizedRock(0.5, 0.1)}
    split = score_labels(halves, pieces, np.ones(8), truth, measured)
    assert (split.found, split.reported, split.precision) == (2, 4, 1.0)
    assert split.d50_true == same.d50_true != same.d50_true_visible
    merged = np.array([1, 1, 1, 1, 1, 3, 0])
    score = score_labels(true_labels, merged, areas, truth, {1: SizedRock(2.0, 9.0), 3: truth[3]})
    assert (score.found, score.merges) == (1, 1)
    # The region of two rocks is matched to the one holding most of it, the larger.
    assert set(score.pairs) == {(1, 2), (3, 3)}
    assert score.recall == 0.5
    assert score.precision == 1.0
    assert score.b_error == 0.0


def test_label_outcomes_say_what_became_of_each_rock() -> None:
    # Rock 1 whole; rock 2 in a region mostly rock 3's; rock 4 in three pieces; rock 5 half in
    # a region with a little ground, half unlabelled; rock 6 untouched; rock 9 not there.
    true_labels = np.array([1, 1, 2, 2, 3, 3, 3, 4, 4, 4] + [5] * 10 + [0, 0, 6])
    labels = np.array([1, 1, 2, 2, 2, 2, 2, 3, 4, 5] + [6] * 5 + [0] * 5 + [6, 6, 0])
    counts = label_outcomes(true_labels, labels, np.ones(23), [1, 2, 4, 5, 6, 9])
    assert counts == {'matched': 1, 'with another rock': 1, 'in pieces': 3, 'short': 1}
    assert label_outcomes(true_labels, true_labels, np.ones(23), [1, 2, 3, 4, 5, 6])['matched'] == 6


def test_each_step_of_the_segmentation_is_reported_with_its_labels() -> None:
    surface = _surface(8.0)
    seen: list[tuple[str, np.ndarray]] = []
    params = SegmentParams(min_rock_b=SMALLEST, min_rock_edges=4.0)
    seg = segment_mesh(
        surface.vertices,
        surface.faces,
        params,
        on_step=lambda name, labels: seen.append((name, labels.copy())),
    )
    names = [name for name, _ in seen]
    assert names == [s for s in STEPS if s in names]
    assert names[:3] == ['search', 'fragments', 'necks'] and 'convex join' in names
    # The last step's labels are the result's, numbered differently.
    last = seen[-1][1]
    pairs = np.unique(np.stack([last, seg.labels]), axis=1)
    assert len(np.unique(pairs[0])) == len(np.unique(pairs[1])) == pairs.shape[1]
    # The search alone leaves the bed in more regions than the clean-ups do.
    assert len(np.unique(seen[0][1])) > len(np.unique(seg.labels))


def test_far_valley_faces_are_in_a_rock_only_as_pieces_joined_to_it() -> None:
    surface = _surface(8.0)

    def run(pieces: bool) -> tuple[dict[str, np.ndarray], np.ndarray]:
        seen: dict[str, np.ndarray] = {}
        params = SegmentParams(min_rock_b=SMALLEST, min_rock_edges=4.0, far_valley_pieces=pieces)
        seg = segment_mesh(
            surface.vertices,
            surface.faces,
            params,
            on_step=lambda name, labels: seen.__setitem__(name, labels.copy()),
        )
        return seen, seg.labels

    handed, out = run(False)
    cut, joined = run(True)
    assert 'valleys all' in handed and 'far pieces' not in handed
    assert 'far pieces' in cut and 'valleys all' not in cut
    # The steps before are the same; the far faces are the valley faces handed back last.
    assert np.array_equal(cut['valleys near'], handed['valleys near'])
    far = (handed['valleys near'] == 0) & (handed['valleys all'] > 0)
    assert far.sum() > 100
    # Handed back whole, every far face is left out at the end; as pieces, those joined stay.
    assert not out[far].any()
    assert 0 < np.count_nonzero(joined[far]) < far.sum()
    # No rock is made of far faces alone: a piece joined to nothing is left out.
    rocks = np.unique(joined[joined > 0])
    anchored = np.unique(joined[(joined > 0) & ~far])
    assert np.array_equal(rocks, anchored)


def test_a_bed_of_a_hundred_rocks_is_segmented_and_measured() -> None:
    # 8 edges across the smallest b, under the default floor of 20 edges: with it, the rocks
    # under 20 edges are fragments and 6 of 61 visible rocks are found. With the floor at 4 edges,
    # measured when written: 32 of 61 found, precision 0.52, median b error 9.4 %, D50 +26 %
    # (the failures are touching rocks taken as one); after 64f7826, 36 found, precision 0.59, D50
    # +38 % against every true rock (+24 % against the visible ones). The bounds catch a step
    # back, not the goal (bench/bench_yardstick.py).
    surface = _surface(8.0)
    truth = _truth(surface)

    def score(params: SegmentParams) -> LabelScore:
        seg = segment_mesh(surface.vertices, surface.faces, params)
        assert SMALLEST / seg.scale.edge == pytest.approx(8.0, rel=0.15)
        rocks = measure_rocks(surface.vertices, seg)
        measured = {r.id: SizedRock(r.b, r.mass) for r in rocks}
        return score_labels(surface.labels, seg.labels, seg.geometry.areas, truth, measured)

    floored = score(SegmentParams(min_rock_b=SMALLEST))
    assert floored.recall < 0.3
    resolved = score(SegmentParams(min_rock_b=SMALLEST, min_rock_edges=4.0))
    assert resolved.visible >= 45
    assert resolved.recall >= 0.45
    assert resolved.precision >= 0.45
    assert resolved.b_error <= 0.12
    assert abs(resolved.d50_error) <= 0.5


def test_a_draped_bed_rises_and_falls_with_the_wave_and_keeps_its_truth() -> None:
    flat = _surface(4.0)
    wavy = drape(flat, 0.15, 3.0)
    assert wavy.faces is flat.faces and wavy.labels is flat.labels and wavy.rocks is flat.rocks
    rise = wavy.vertices[:, 2] - flat.vertices[:, 2]
    assert np.array_equal(wavy.vertices[:, :2], flat.vertices[:, :2])
    assert rise.min() >= -0.15 and rise.max() <= 0.15
    x, y = flat.vertices[:, 0], flat.vertices[:, 1]
    expected = 0.15 * np.sin(2 * np.pi * x / 3.0) * np.cos(2 * np.pi * y / 3.0)
    assert np.allclose(rise, expected)
    with pytest.raises(StockpileError):
        drape(flat, 0.15, 0.0)


def test_relief_roughens_the_ground_as_dense_matching_does() -> None:
    # Point noise alone is averaged away by Poisson; a relief correlated over cells is not.
    cell = SMALLEST / 4

    def ground_heights(surface: BedSurface) -> np.ndarray:
        centres = surface.vertices[surface.faces].mean(axis=1)
        rocks = np.concatenate([r.mesh.vertices for r in _bed()])
        # The strip of open ground the survey saw round the rocks (it reaches a smallest b out).
        lo, hi = rocks[:, :2].min(axis=0), rocks[:, :2].max(axis=0)
        gap = np.maximum(lo - centres[:, :2], centres[:, :2] - hi).max(axis=1)
        strip = (gap > 0.3 * SMALLEST) & (gap < 0.7 * SMALLEST)
        return centres[strip & (surface.labels == 0), 2]

    plain = ground_heights(_surface(4.0))
    rough = bed_surface(_bed(), cell, np.random.default_rng(2), noise_cells=0.2, relief_cells=0.3)
    heights = ground_heights(rough)
    assert len(plain) > 300 and len(heights) > 300
    # Measured when written: 0.04 and 0.22 cells.
    assert plain.std() < 0.08 * cell
    assert 0.15 * cell < heights.std() < 0.35 * cell


def test_estimated_normals_follow_the_surface_and_face_the_survey() -> None:
    rng = np.random.default_rng(4)
    # A dome seen from above by rays falling straight down and 29 degrees off it.
    xy = rng.uniform(-0.5, 0.5, size=(4000, 2))
    points = np.column_stack([xy, np.sqrt(1.0 - np.sum(xy**2, axis=1))])
    tilt = np.deg2rad(29.0)
    rays = np.where(
        (np.arange(len(points)) % 2 == 0)[:, None],
        [0.0, 0.0, -1.0],
        [np.sin(tilt), 0.0, -np.cos(tilt)],
    )
    # As bed_surface asks for them: each sensor a step back along its ray.
    n, _ = estimate_normals(points, points - rays, 20, 0.01)
    assert np.all(np.einsum('ij,ij->i', n, rays) < 0)
    assert np.median(np.einsum('ij,ij->i', n, points)) > np.cos(np.deg2rad(3.0))


def test_fines_count_as_barely_seen_rocks_and_their_clusters_as_false() -> None:
    # Rock 1 is of interest; rocks 2-5 are fines under a smallest rock of b 1.
    sizes = {1: 2.0, 2: 0.5, 3: 0.5, 4: 0.5, 5: 0.5}
    truth = {k: SizedRock(b, b**3, 0.8) for k, b in sizes.items()}
    true_labels = np.array([1, 1, 1, 2, 2, 3, 3, 4, 4, 5, 5])
    areas = np.ones(11)
    # Rock 1 found, rock 2 found alone, rocks 3, 4 and 5 taken for one rock.
    labels = np.array([1, 1, 1, 2, 2, 3, 3, 3, 3, 3, 3])
    measured = {1: SizedRock(2.0, 8.0), 2: SizedRock(0.5, 0.1), 3: SizedRock(1.0, 1.0)}
    every = score_labels(true_labels, labels, areas, truth, measured)
    assert (every.visible, every.found, every.clusters, every.precision) == (5, 2, 0, 2 / 3)
    fines = score_labels(true_labels, labels, areas, truth, measured, min_b=1.0)
    assert (fines.visible, fines.found, fines.recall) == (1, 1, 1.0)
    # The fine found alone counts neither way; the cluster of three counts against precision.
    assert (fines.clusters, fines.precision) == (1, 0.5)
