from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from stockpile_ros.errors import StockpileError
from stockpile_ros.result import GradationCurve, Intervals
from stockpile_ros.segment.gradation import PERCENTS, gradation, load_class_table, percent_size
from stockpile_ros.segment.qa import decide

CONFIG = Path(__file__).resolve().parents[1] / 'config'


def _exact(curve: GradationCurve) -> Intervals:
    """Intervals of no width: the verdict then reads the measured values alone."""
    by_count = {
        f'd{p}': percent_size(curve.sizes, curve.percent_passing_count, p) for p in PERCENTS
    }
    return Intervals(
        'exact', 0.9, 0, 0, 0.0,
        mass={key: [value, value] for key, value in curve.characteristic.items()},
        count={key: [value, value] for key, value in by_count.items()},
        cu=[curve.cu, curve.cu], cc=[curve.cc, curve.cc],
    )  # fmt: skip


def test_hand_computed_gradation() -> None:
    g = gradation([0.4, 0.1, 0.3, 0.2], [4.0, 1.0, 3.0, 2.0])
    assert g.sizes == [0.1, 0.2, 0.3, 0.4]
    assert g.percent_passing_mass == pytest.approx([10, 30, 60, 100])
    assert g.percent_passing_count == pytest.approx([25, 50, 75, 100])
    assert g.d10 == pytest.approx(0.1)
    assert g.d30 == pytest.approx(0.2)
    assert g.d60 == pytest.approx(0.3)
    assert g.d100 == pytest.approx(0.4)
    # Linear in log size between (0.2, 30 %) and (0.3, 60 %).
    assert g.d50 == pytest.approx(math.exp(math.log(0.2) + 20 / 30 * math.log(1.5)))
    assert g.d85 == pytest.approx(math.exp(math.log(0.3) + 25 / 40 * math.log(4 / 3)))
    assert g.cu == pytest.approx(3.0)
    assert g.cc == pytest.approx(0.04 / 0.03)
    assert g.rock_count == 4 and g.total_mass == pytest.approx(10)
    assert g.characteristic['d50'] == g.d50 and list(g.characteristic) == [
        f'd{p}' for p in PERCENTS
    ]


def test_undefined_below_the_first_point_and_ties() -> None:
    g = gradation([0.2, 0.2, 0.5], [3.0, 3.0, 4.0])
    assert g.percent_passing_mass == pytest.approx([60, 60, 100])
    assert g.d10 is None and g.cu is None and g.cc is None
    assert g.d60 == pytest.approx(0.2)
    assert percent_size([], [], 50) is None
    empty = gradation([], [])
    assert empty.d50 is None and empty.rock_count == 0


def test_class_table_and_check() -> None:
    table = load_class_table()
    spec = table['classes']['III']
    assert spec['limits']['d50'] == pytest.approx([11.5 * 0.0254, 14.0 * 0.0254])
    inch = 0.0254
    curve = gradation([0.1], [1.0])
    good = replace(curve, d15=9 * inch, d50=12 * inch, d85=17 * inch, d100=20 * inch)
    result = decide(good, spec, _exact(good))
    assert (result.class_name, result.basis, result.checked) == ('III', 'mass', True)
    assert (result.verdict, result.passed, result.reasons) == ('PASS', True, [])
    bad = replace(good, d50=16 * inch, d15=None)
    result = decide(bad, spec, _exact(bad))
    assert result.verdict == 'FAIL' and result.passed is False
    # What fails first, then what is left undecided.
    assert len(result.reasons) == 2
    assert 'D50' in result.reasons[0] and 'above' in result.reasons[0]
    assert result.reasons[1].startswith('D15 by mass undefined')


def test_a_limit_under_the_smallest_resolved_rock_is_undecided() -> None:
    spec = load_class_table()['classes']['III']
    inch = 0.0254
    curve = gradation([0.1], [1.0])
    good = replace(curve, d15=9 * inch, d50=12 * inch, d85=17 * inch, d100=20 * inch)
    # Resolved down to the D15 limits' lower end: the check reads the values as before.
    assert decide(good, spec, _exact(good), resolved_b=7.3 * inch).verdict == 'PASS'
    # Rocks under 8 in not resolved: D15's limits (7.3-10.5 in) cannot be read, the rest can.
    coarse = decide(good, spec, _exact(good), resolved_b=8 * inch)
    assert coarse.verdict == 'UNDECIDED' and coarse.passed is None
    assert [r.status for r in coarse.limits] == ['undecided', 'pass', 'pass', 'pass']
    assert len(coarse.reasons) == 1 and 'D15 by mass' in coarse.reasons[0]
    assert 'under the smallest rock this run resolves (0.203 m)' in coarse.reasons[0]
    # A D50 far above its maximum does not fail where its limits lie under the resolved rock.
    bad = replace(good, d50=16 * inch)
    assert decide(bad, spec, _exact(bad)).verdict == 'FAIL'
    unresolved = decide(bad, spec, _exact(bad), resolved_b=12 * inch)
    assert unresolved.verdict == 'UNDECIDED'
    assert [r.key for r in unresolved.limits if r.status == 'undecided'] == ['d15', 'd50']


def test_a_class_by_count_reads_the_count_curve() -> None:
    # FP-14 class 1 by count: D15 3-6 in, D50 5-8 in, D85 7-11 in, D100 9-15 in.
    table = load_class_table(CONFIG / 'fp14_riprap_classes.yaml')
    assert table['basis'] == 'count' and sorted(table['classes']) == [str(k) for k in range(1, 9)]
    spec = table['classes']['1']
    inch = 0.0254
    # Twenty rocks of 4.5-7.5 in and one 15 in boulder: class 1 by count, while by mass the
    # boulder carries 40 % of the pile and D85 by mass (11.7 in) is past class 1's D85 by count.
    sizes = [k * inch for k in np.linspace(4.5, 7.5, 20)] + [15 * inch]
    masses = [2650 * s**3 for s in sizes]
    grad = gradation(sizes, masses)
    by_count = decide(grad, spec, _exact(grad))
    assert by_count.basis == 'count'
    assert by_count.passed is True, by_count.reasons
    assert grad.d85 is not None and grad.d85 > 11 * inch
    # The same rocks fail against the mass-based class I of the default table (D50 at most
    # 6.9 in by mass).
    by_mass = decide(grad, load_class_table()['classes']['I'], _exact(grad))
    assert by_mass.passed is False
    assert any(r.startswith('D50 by mass') and 'above' in r for r in by_mass.reasons)


def test_bad_class_table(tmp_path) -> None:
    path = tmp_path / 'bad.yaml'
    path.write_text('classes: {A: {limits: {d42: [1, 2]}}}\n')
    with pytest.raises(StockpileError):
        load_class_table(path)
