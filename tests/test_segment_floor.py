"""The floor of a mesh nothing vouches for: lowered while the sizes pile up against it."""

from __future__ import annotations

import functools

import numpy as np
import pytest

from stockpile_ros.artefacts import load
from stockpile_ros.cli import main
from stockpile_ros.meshio import LabelledMesh, write_labelled_mesh
from stockpile_ros.result import FloorTry, Report
from stockpile_ros.segment.measure import MeasureParams
from stockpile_ros.segment.params import SegmentParams
from stockpile_ros.segment.pipeline import (
    FLOOR_STEPS,
    Measured,
    floor_warnings,
    kept_floor,
    segment_and_measure,
    settle_floor,
)
from stockpile_ros.tools.evaluation.labels import LabelScore, SizedRock, score_labels
from stockpile_ros.tools.sim.bed import BedConfig, BedSurface, bed_surface, build_bed
from stockpile_ros.tools.sim.pile import Gradation


@functools.lru_cache(maxsize=1)
def _bed() -> BedSurface:
    """150 rocks of b 0.1-0.3 m, meshed clean at 8 edge lengths across the smallest."""
    cfg = BedConfig(rocks=150, gradation=Gradation((0.1, 0.3), (0.0, 100.0)))
    return bed_surface(build_bed(np.random.default_rng(1), cfg), 0.1 / 8, np.random.default_rng(1))


def _score(surface: BedSurface, measured: Measured) -> LabelScore:
    seg = measured.segmentation
    truth = {
        k: SizedRock(r['b'], r['mass'], r['visible_fraction']) for k, r in surface.rocks.items()
    }
    found = {r.id: SizedRock(r.b, r.mass) for r in measured.rocks}
    return score_labels(surface.labels, seg.labels, seg.geometry.areas, truth, found)


def test_a_clean_mesh_finer_than_the_floor_has_it_lowered_towards_its_smallest_rocks() -> None:
    surface = _bed()
    v, f = surface.vertices, surface.faces
    measured, tried = settle_floor(v, f, SegmentParams(), MeasureParams())
    # At 20 edge lengths the rocks pile up against the floor (clusters of them); lower floors are
    # tried a band (a factor sqrt 2) at a time.
    assert tried[0].edges == 20.0 and tried[0].cut
    assert [t.edges for t in tried] == pytest.approx(
        [20.0 / np.sqrt(2.0) ** k for k in range(len(tried))]
    )
    assert 1 < len(tried) <= FLOOR_STEPS + 1
    (kept,) = [t for t in tried if t.kept]
    assert measured.segmentation.params.min_rock_edges == kept.edges < 20.0
    assert sum(kept.bands) == len(measured.rocks)
    lowered = _score(surface, measured)
    default = _score(surface, segment_and_measure(v, f, SegmentParams(), MeasureParams()))
    assert lowered.recall >= max(0.5, 3 * default.recall) and lowered.precision >= 0.7
    # A smallest rock asked for at or above the floor: nothing searched.
    asked = SegmentParams(min_rock_b=0.3)
    again, none = settle_floor(v, f, asked, MeasureParams())
    assert none == [] and again.segmentation.params == asked
    # Under it (0.12 m, the floor at 20 edges being 0.25 m): searched, never under what is asked.
    again, tried = settle_floor(v, f, SegmentParams(min_rock_b=0.12), MeasureParams())
    assert len(tried) > 1 and min(t.min_rock_b for t in tried) == pytest.approx(0.12, rel=1e-6)
    assert [t.asked for t in tried] == [t.min_rock_b <= 0.12 * (1 + 1e-6) for t in tried]
    assert again.segmentation.scale.min_rock_b >= 0.12 * (1 - 1e-6)


def test_the_floor_kept_is_where_the_sizes_fall_off_with_the_rise_below_it() -> None:
    def t(edges: float, *bands: int, cut: bool) -> FloorTry:
        return FloorTry(edges, edges / 100, list(bands), cut)

    # Falling off at once: nothing searched beyond it.
    assert kept_floor([t(20, 3, 5, 4, cut=False)]) == 0
    # Piled up at 20, 14 and 10; at 7 the lowest band is the fullest, as a pile's smallest make it.
    bar = [t(20, 69, 2, cut=True), t(14, 99, 13, cut=True), t(10, 137, 34, cut=True)]
    assert kept_floor([*bar, t(7, 109, 82, 33, cut=False)]) == 3
    # A lower band holding fewer than the next: the rise ended above it, the floor above is kept
    # (a bed with the noise of a mesh from photos, its smallest rock at 19 edge lengths).
    assert kept_floor([t(20, 114, 36, 15, cut=True), t(14, 62, 102, 36, cut=False)]) == 0
    assert kept_floor([*bar[:2], t(10, 61, 87, 23, cut=False)]) == 1
    # Piled up at every floor: the first; unless the last is the smallest rock asked for.
    assert kept_floor([*bar, t(7, 200, 82, cut=True)]) == 0
    asked = FloorTry(8.7, 0.1, [129, 54], True, asked=True)
    assert kept_floor([*bar, asked]) == 3


def test_how_the_floor_was_set_is_said() -> None:
    def t(edges: float, *bands: int, cut: bool, kept: bool = False) -> FloorTry:
        return FloorTry(edges, edges * 0.0115, list(bands), cut, kept=kept)

    bar = [t(20, 69, 2, cut=True), t(14.1, 99, 13, cut=True), t(10, 137, 34, cut=True)]
    (text,) = floor_warnings([*bar, t(7.07, 109, 82, 33, cut=False, kept=True)], 'm')
    assert '20: 69, 2 of 71; 14.1: 99, 13 of 112; 10: 137, 34 of 171; 7.07: 109, 82 of 224' in text
    assert 'Kept 7.07 (0.0813 m)' in text and 'fall off towards this one' in text
    assert 'segment.min_rock_edges=20' in text
    asked = FloorTry(8.7, 0.1, [129, 54], True, asked=True, kept=True)
    (text,) = floor_warnings([*bar, asked], 'm')
    assert 'Kept 8.7 (0.1 m)' in text and 'it is the smallest rock asked for' in text
    (text,) = floor_warnings(
        [t(20, 114, 36, cut=True, kept=True), t(14.1, 62, 102, cut=False)], 'm'
    )
    assert 'Kept 20 ' in text and 'pieces of rocks' in text
    (text,) = floor_warnings([t(20, 69, 2, cut=True, kept=True), t(14.1, 99, 13, cut=True)], 'm')
    assert 'piled up against every floor' in text and 'Kept 20 (0.23 m)' in text
    # Fell off at the first floor, or not searched: nothing to say.
    assert floor_warnings([t(20, 3, 5, cut=False, kept=True)], 'm') == []
    assert floor_warnings([], 'm') == []


def test_stockpile_segment_searches_the_floor_of_another_tools_mesh(tmp_path) -> None:  # type: ignore[no-untyped-def]
    surface = _bed()
    path = tmp_path / 'bed.ply'
    write_labelled_mesh(
        path,
        LabelledMesh(surface.vertices, surface.faces, np.zeros(len(surface.faces), dtype=np.int32)),
    )
    out = tmp_path / 'out'
    assert main(['segment', str(path), '--units', 'm', '--out', str(out)]) == 0
    report = load(Report, out / 'report.json')
    (kept,) = [t for t in report.segmentation.floors if t.kept]
    assert report.segmentation.min_rock_edges == kept.edges < 20.0
    assert report.segmentation.scale.min_rock_b == pytest.approx(kept.min_rock_b)
    assert len(report.rocks) == sum(kept.bands)
    assert any(
        w.startswith('Floors tried for the smallest rock this mesh resolves')
        for w in report.warnings
    )
    # Set explicitly, the floor is the one asked for.
    again = tmp_path / 'again'
    flags = ['--units', 'm', '--set', 'segment.min_rock_edges=20', '--out', str(again)]
    assert main(['segment', str(path), *flags]) == 0
    report = load(Report, again / 'report.json')
    assert report.segmentation.floors == [] and report.segmentation.min_rock_edges == 20.0
