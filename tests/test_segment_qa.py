from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from stockpile_ros.result import ClassDecision, GradationCurve, Intervals
from stockpile_ros.segment.gradation import gradation, load_class_table
from stockpile_ros.segment.provenance import Provenance, changed_parameters, fingerprint
from stockpile_ros.segment.qa import (
    ReportOptions,
    bootstrap_intervals,
    decide,
    refuse,
    report_options,
    rosin_rammler,
    sieve_table,
)

CONFIG = Path(__file__).resolve().parents[1] / 'config'
CLASS_I = load_class_table()['classes']['I']
D50_MIN = CLASS_I['limits']['d50'][0]


def _pile(d50: float, n: int = 200, seed: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Rock sizes b log-normal (sigma 0.25), masses of cubes of side b; rescaled to ``d50``."""
    rng = np.random.default_rng(seed)
    b = np.exp(rng.normal(0.0, 0.25, n))
    masses = 2650.0 * b**3
    b *= d50 / gradation(b, masses).d50
    return b, 2650.0 * b**3


def _verdict(
    d50: float, spec: dict, rel_scale: float = 0.01
) -> tuple[GradationCurve, Intervals, ClassDecision]:
    sizes, masses = _pile(d50)
    grad = gradation(sizes, masses)
    intervals = bootstrap_intervals(sizes, masses, rel_scale, ReportOptions(resamples=400))
    return grad, intervals, decide(grad, spec, intervals)


def test_d50_within_its_interval_of_a_limit_is_undecided() -> None:
    spec = {'name': 'I (D50)', 'basis': 'mass', 'limits': {'d50': CLASS_I['limits']['d50']}}
    grad, intervals, result = _verdict(1.01 * D50_MIN, spec)
    lo, hi = intervals.mass['d50']
    # The point value passes the limit, but its interval reaches below it.
    assert lo < D50_MIN < grad.d50 < hi
    assert result.verdict == 'UNDECIDED' and result.passed is None
    (row,) = result.limits
    assert row.status == 'undecided' and 0 < row.margin < hi - lo
    assert 'straddles the minimum' in result.reasons[0]


def test_well_inside_passes_and_well_outside_fails() -> None:
    spec = {'name': 'I (D50)', 'basis': 'mass', 'limits': {'d50': CLASS_I['limits']['d50']}}
    mid = 0.5 * sum(CLASS_I['limits']['d50'])
    _, _, inside = _verdict(mid, spec)
    assert inside.verdict == 'PASS' and inside.passed is True and inside.reasons == []
    _, _, outside = _verdict(0.6 * D50_MIN, spec)
    assert outside.verdict == 'FAIL' and outside.passed is False
    assert 'below the minimum' in outside.reasons[0]
    # A limit broken for certain outweighs one left undecided.
    both = {**spec, 'limits': {**spec['limits'], 'd15': [0.0, 10.0]}}
    _, _, failed = _verdict(0.6 * D50_MIN, both)
    assert failed.verdict == 'FAIL'


def test_the_scale_uncertainty_widens_the_size_intervals_not_cu() -> None:
    sizes, masses = _pile(0.16)
    tight = bootstrap_intervals(sizes, masses, 0.0, ReportOptions(resamples=400))
    loose = bootstrap_intervals(sizes, masses, 0.1, ReportOptions(resamples=400))
    width = {k: v.mass['d50'][1] - v.mass['d50'][0] for k, v in (('t', tight), ('l', loose))}
    assert width['l'] > 1.5 * width['t']
    assert loose.cu == pytest.approx(tight.cu, rel=0.05)
    # A fixed seed reproduces the intervals.
    assert bootstrap_intervals(sizes, masses, 0.0, ReportOptions(resamples=400)) == tight


def test_a_run_without_scale_gets_no_verdict() -> None:
    result = refuse(CLASS_I)
    assert result.checked is False and result.passed is None
    assert result.verdict == 'REFUSED' and 'model units' in result.reasons[0]
    assert refuse(None).verdict == 'NOT CHECKED'


def test_sieve_table_reads_the_step_curve() -> None:
    grad = gradation([0.03, 0.06, 0.12], [1.0, 2.0, 7.0])
    rows = sieve_table(grad, 'mm')
    by_size = {round(r.size_display, 2): (r.mass, r.count) for r in rows}
    # From the opening below the smallest rock to the first at or above the largest.
    assert min(by_size) == 25.0 and max(by_size) == 125.0
    assert by_size[25.0] == (0.0, 0.0)
    assert by_size[50.0] == pytest.approx((10.0, 100 / 3))
    assert by_size[100.0] == pytest.approx((30.0, 200 / 3))
    assert by_size[125.0] == pytest.approx((100.0, 100.0))
    inch = sieve_table(grad, 'in')
    assert inch[0].size_display == 1.0 and inch[-1].size_display == 5.0


def test_rosin_rammler_recovers_its_own_curve() -> None:
    # Sizes on a Rosin-Rammler mass curve (d_c 0.2 m, n 3): masses are the curve's increments.
    sizes = np.geomspace(0.05, 0.5, 40)
    passing = 1 - np.exp(-((sizes / 0.2) ** 3))
    masses = np.diff(np.concatenate([[0.0], passing]))
    fit = rosin_rammler(gradation(sizes, masses))
    assert fit is not None
    assert fit.d_c == pytest.approx(0.2, rel=0.03) and fit.n == pytest.approx(3, rel=0.05)
    assert rosin_rammler(gradation([0.1, 0.2], [1.0, 1.0])) is None


def test_fingerprints(tmp_path) -> None:
    file = tmp_path / 'mesh.ply'
    file.write_bytes(b'ply\n')
    digest, how = fingerprint(file)
    assert len(digest) == 64 and 'first and last MiB' in how
    bag = tmp_path / 'bag'
    bag.mkdir()
    (bag / 'metadata.yaml').write_text('rosbag2_bagfile_information: {}\n')
    (bag / 'bag_0.mcap').write_bytes(b'x' * 10)
    first, _ = fingerprint(bag)
    (bag / 'bag_0.mcap').write_bytes(b'x' * 11)
    assert fingerprint(bag)[0] != first
    missing = Provenance.for_input(tmp_path / 'gone', {'report.site': 'Q'}, {})
    assert missing.input_sha256 == '' and 'not fingerprinted' in missing.fingerprint_method
    assert missing.site == 'Q' and missing.created.endswith('+00:00')


def test_changed_parameters_and_options() -> None:
    assert changed_parameters({'a': 1, 'b': 2}, {'a': 1, 'b': 3}) == {'b': 2}
    opts = report_options({'report.length_unit': 'in', 'report.seed': 4, 'segment.mode': 'x'})
    assert opts.length_unit == 'in' and opts.seed == 4 and opts.mass_unit == 'kg'
    assert math.isclose(opts.confidence, 0.9)
