"""The figures a QA engineer signs: intervals, the verdict against a class, sieves, units.

Intervals come from a bootstrap over the rocks (``resamples`` draws of as many rocks, with
replacement, a fixed ``seed`` so that a report can be reproduced), each draw's lengths multiplied
by ``1 + u z`` with ``u`` the scale's relative uncertainty (``Report.scale.rel_uncertainty``)
and ``z`` a standard normal draw: the spread of the sample and the doubt on the metric scale in
one interval. Percent passing by mass is a ratio of masses, so a scale error moves every size by
the same factor and leaves the curve's shape alone: Cu and Cc (ratios of sizes) carry only the
sampling spread.

The verdict against a class: each limit is ``pass`` when the measured value's interval lies within
it, ``fail`` when the interval lies wholly on the wrong side, ``undecided`` when it straddles the
limit or the value is undefined. The class is ``FAIL`` when any limit fails, else ``UNDECIDED``
when any is undecided, else ``PASS``. Without a metric scale (``scale.method == 'none'``) no class
is checked: the sizes are in model units and a limit in metres says nothing of them.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from typing import Annotated, Any, Literal

import numpy as np
import numpy.typing as npt

from ..ranges import Range
from ..result import (
    Basis,
    ClassDecision,
    GradationCurve,
    Intervals,
    LimitRow,
    LimitStatus,
    RosinRammler,
    Sieve,
    Verdict,
)
from .gradation import PERCENTS, percent_size

__all__ = [
    'LENGTH_UNITS',
    'MASS_UNITS',
    'LengthUnit',
    'MassUnit',
    'ReportOptions',
    'bootstrap_intervals',
    'decide',
    'refuse',
    'report_options',
    'rosin_rammler',
    'sieve_table',
]

LengthUnit = Literal['mm', 'in']
MassUnit = Literal['kg', 'lb']

#: Metres per display length unit.
LENGTH_UNITS: dict[str, float] = {'mm': 1e-3, 'in': 0.0254}
#: Kilograms per display mass unit.
MASS_UNITS: dict[str, float] = {'kg': 1.0, 'lb': 0.45359237}

# Sieve and gauge sizes of the table, in the display unit. Metric: the ISO 565 / ASTM E11 square
# openings up to 125 mm, then the R10 preferred numbers used for gauges of larger stone. Inch: the
# ASTM E11 inch designations up to 5 in, then the whole-inch sizes riprap classes are written in.
_SIEVES: dict[str, tuple[float, ...]] = {
    'mm': (
        4.75,
        9.5,
        12.5,
        19.0,
        25.0,
        37.5,
        50.0,
        63.0,
        75.0,
        90.0,
        100.0,
        125.0,
        160.0,
        200.0,
        250.0,
        315.0,
        400.0,
        500.0,
        630.0,
        800.0,
        1000.0,
        1250.0,
        1600.0,
    ),
    'in': (
        0.375,
        0.5,
        0.75,
        1.0,
        1.5,
        2.0,
        2.5,
        3.0,
        3.5,
        4.0,
        5.0,
        6.0,
        8.0,
        10.0,
        12.0,
        15.0,
        18.0,
        21.0,
        24.0,
        30.0,
        36.0,
        42.0,
        48.0,
        60.0,
    ),
}


@dataclass(frozen=True)
class ReportOptions:
    """What the result folder's report shows and how its intervals are computed.

    Attributes:
        site: Quarry or site name, printed on the report ('' when not given).
        pile: Name of the stockpile, printed on the report ('' when not given).
        operator: Who ran the measurement, printed on the report ('' when not given).
        length_unit: Length unit of the page and PDF (report.json and rocks.csv stay in metres).
        mass_unit: Mass unit of the page and PDF (report.json and rocks.csv stay in kilograms).
        resamples: Bootstrap draws over the rocks for the intervals.
        confidence: Two-sided confidence level of the intervals.
        seed: Seed of the bootstrap (fixed, so a report can be reproduced).
        rosin_rammler: Fit and draw a Rosin-Rammler curve to the percent passing by mass.

    """

    site: str = ''
    pile: str = ''
    operator: str = ''
    length_unit: LengthUnit = 'mm'
    mass_unit: MassUnit = 'kg'
    resamples: Annotated[int, Range(100, 100_000)] = 1000
    confidence: Annotated[float, Range(0.5, 0.999)] = 0.9
    seed: Annotated[int, Range(0, 1_000_000)] = 0
    rosin_rammler: bool = True

    def as_dict(self) -> dict[str, Any]:
        """Return the options as a plain dict."""
        return asdict(self)


def report_options(values: Mapping[str, Any]) -> ReportOptions:
    """Build the options from parameter values by dotted name (``report.*``; others ignored)."""
    prefix = 'report.'
    return ReportOptions(**{k[len(prefix) :]: v for k, v in values.items() if k.startswith(prefix)})


def _curve(sizes: npt.NDArray[np.float64], weights: npt.NDArray[np.float64]) -> Any:
    """Sorted sizes and percent passing by ``weights``, ties evaluated at their last member."""
    order = np.argsort(sizes, kind='stable')
    s, w = sizes[order], weights[order]
    total = float(w.sum())
    if len(s) == 0 or total <= 0:
        return s, None
    last = np.searchsorted(s, s, side='right') - 1
    return s, 100.0 * np.cumsum(w)[last] / total


def _characteristic(
    sizes: npt.NDArray[np.float64], weights: npt.NDArray[np.float64]
) -> dict[int, float | None]:
    s, passing = _curve(sizes, weights)
    if passing is None:
        return dict.fromkeys(PERCENTS)
    return {p: percent_size(s, passing, p) for p in PERCENTS}


def _coefficients(d: Mapping[int, float | None]) -> tuple[float | None, float | None]:
    d10, d30, d60 = d[10], d[30], d[60]
    cu = d60 / d10 if d10 and d60 else None
    cc = d30 * d30 / (d10 * d60) if d10 and d30 and d60 else None
    return cu, cc


def bootstrap_intervals(
    sizes: npt.ArrayLike,
    masses: npt.ArrayLike,
    rel_scale_uncertainty: float | None,
    options: ReportOptions | None = None,
) -> Intervals:
    """Return confidence intervals of D10..D100 (by mass and by count), Cu and Cc.

    Args:
        sizes: Size of each rock [m].
        masses: Mass of each rock [kg] (any unit: only shares of the total are used).
        rel_scale_uncertainty: The scale's relative standard uncertainty (None or NaN: 0).
        options: Resamples, confidence and seed.

    Returns:
        The intervals; an end is None where more than the tail's share of the draws leave the
        value undefined (a draw whose smallest rock holds more than p % of the mass says nothing
        below it).

    """
    opts = options or ReportOptions()
    s = np.asarray(sizes, dtype=np.float64).ravel()
    m = np.asarray(masses, dtype=np.float64).ravel()
    ok = np.isfinite(s) & np.isfinite(m) & (s > 0) & (m >= 0)
    s, m = s[ok], m[ok]
    u = float(rel_scale_uncertainty or 0.0)
    u = u if math.isfinite(u) else 0.0
    rng = np.random.default_rng(opts.seed)
    draws = opts.resamples
    keys = [*(f'mass:d{p}' for p in PERCENTS), *(f'count:d{p}' for p in PERCENTS), 'cu', 'cc']
    table = np.full((draws, len(keys)), np.nan)
    n = len(s)
    for k in range(draws if n else 0):
        pick = rng.integers(0, n, n)
        factor = max(1.0 + u * float(rng.standard_normal()), 1e-6)
        ss, mm = s[pick], m[pick]
        by_mass = _characteristic(ss, mm)
        by_count = _characteristic(ss, np.ones(n))
        cu, cc = _coefficients(by_mass)
        row = [*(by_mass[p] for p in PERCENTS), *(by_count[p] for p in PERCENTS)]
        table[k, : len(row)] = [np.nan if x is None else x * factor for x in row]
        table[k, len(row) :] = [np.nan if x is None else x for x in (cu, cc)]
    tail = 0.5 * (1.0 - opts.confidence)
    bounds: dict[str, list[float | None]] = {}
    for j, key in enumerate(keys):
        # An undefined draw lies below every defined one (the value is under its smallest rock).
        col = np.sort(np.where(np.isfinite(table[:, j]), table[:, j], -np.inf))
        if not n:
            bounds[key] = [None, None]
            continue
        ends = (
            col[math.floor(tail * (draws - 1))],
            col[math.ceil((1 - tail) * (draws - 1))],
        )
        bounds[key] = [float(x) if math.isfinite(x) else None for x in ends]
    return Intervals(
        method='bootstrap over rocks, lengths times (1 + scale uncertainty x normal draw)',
        confidence=opts.confidence,
        resamples=draws,
        seed=opts.seed,
        scale_rel_uncertainty=u,
        mass={f'd{p}': bounds[f'mass:d{p}'] for p in PERCENTS},
        count={f'd{p}': bounds[f'count:d{p}'] for p in PERCENTS},
        cu=bounds['cu'],
        cc=bounds['cc'],
    )


def _limit_row(
    key: str,
    basis: str,
    bound: Sequence[float | None],
    value: float | None,
    interval: Sequence[float | None],
    resolved_b: float,
) -> LimitRow:
    lo_lim, hi_lim = bound
    lo, hi = interval
    label = f'{key.upper()} by {basis}'
    margins = [
        x
        for x in (
            (value - lo_lim) if value is not None and lo_lim is not None else None,
            (hi_lim - value) if value is not None and hi_lim is not None else None,
        )
        if x is not None
    ]
    margin = min(margins) if margins else None
    status: LimitStatus
    unresolved = [x for x in (lo_lim, hi_lim) if x is not None and x < resolved_b]
    if unresolved:
        # Rocks under the smallest one the segmentation keeps are joined to a neighbour or
        # dropped, which moves every size near the limit: neither side of it can be told.
        status = 'undecided'
        why = (
            f'{label}: its limit {min(unresolved):.3f} m is under the smallest rock this run '
            f'resolves ({resolved_b:.3f} m); capture the pile closer or reconstruct it finer'
        )
    elif (hi_lim is not None and lo is not None and lo > hi_lim) or (
        lo_lim is not None and hi is not None and hi < lo_lim
    ):
        status = 'fail'
        side = (
            'above the maximum'
            if lo_lim is None or (hi is not None and hi >= lo_lim)
            else ('below the minimum')
        )
        why = f'{label}: the whole interval lies {side}'
    elif (
        value is not None
        and lo is not None
        and hi is not None
        and (lo_lim is None or lo >= lo_lim)
        and (hi_lim is None or hi <= hi_lim)
    ):
        status, why = 'pass', ''
    else:
        status = 'undecided'
        if value is None:
            why = f'{label} undefined (too few rocks, or the smallest holds too much of the pile)'
        elif lo is None or hi is None:
            why = f'{label}: the lower end of its interval is undefined'
        else:
            crossed = [
                f'{name} {x:.3f} m'
                for name, x in (('minimum', lo_lim), ('maximum', hi_lim))
                if x is not None and lo < x < hi
            ]
            why = f'{label}: its interval {lo:.3f}-{hi:.3f} m straddles the ' + ' and the '.join(
                crossed or ['limit']
            )
    limit = lo_lim if lo_lim is not None else hi_lim
    return LimitRow(
        key=key,
        min=lo_lim,
        max=hi_lim,
        value=value,
        interval=[lo, hi],
        margin=margin,
        margin_rel=margin / limit if margin is not None and limit else None,
        status=status,
        reason=why,
    )


def _not_checked() -> ClassDecision:
    return ClassDecision(None, None, checked=False, passed=None, verdict='NOT CHECKED')


def decide(
    grad: GradationCurve,
    spec: Mapping[str, Any] | None,
    intervals: Intervals,
    resolved_b: float = 0.0,
) -> ClassDecision:
    """Check a class: the limits table of report.json and a PASS/FAIL/UNDECIDED verdict.

    Args:
        grad: The gradation curve (its sizes by mass, or its curve by count).
        spec: The class entry of the class table, or None.
        intervals: What :func:`bootstrap_intervals` returned for the same rocks.
        resolved_b: b of the smallest rock the segmentation kept [m] (``RockScale.min_rock_b``):
            a limit under it is undecided whatever the value, since the rocks that would
            decide it were not resolved.

    Returns:
        The decision; ``passed`` is True for PASS, False for FAIL and None for UNDECIDED;
        ``reasons`` says why the verdict is not PASS.

    """
    if spec is None:
        return _not_checked()
    basis: Basis = 'count' if spec.get('basis') == 'count' else 'mass'
    by_key = intervals.of(basis)
    rows = []
    for key, bound in spec['limits'].items():
        if basis == 'count':
            value = percent_size(grad.sizes, grad.percent_passing_count, float(key[1:]))
        else:
            value = grad.characteristic[key]
        rows.append(_limit_row(key, basis, bound, value, by_key[key], resolved_b))
    states = {r.status for r in rows}
    verdict: Verdict = (
        'FAIL' if 'fail' in states else 'UNDECIDED' if 'undecided' in states else 'PASS'
    )
    order = ['fail', 'undecided'] if verdict == 'FAIL' else ['undecided']
    return ClassDecision(
        class_name=str(spec['name']),
        basis=basis,
        checked=True,
        passed={'PASS': True, 'FAIL': False}.get(verdict),
        verdict=verdict,
        reasons=[r.reason for state in order for r in rows if r.status == state],
        limits=rows,
        standard=str(spec.get('standard', '')),
        edition=str(spec.get('edition', '')),
        caveat=str(spec.get('caveat', '')),
        note=str(spec.get('note', '')),
    )


def refuse(spec: Mapping[str, Any] | None) -> ClassDecision:
    """Return the class check of a run without metric scale: no verdict, and why."""
    if spec is None:
        return _not_checked()
    return ClassDecision(
        class_name=str(spec['name']),
        basis='count' if spec.get('basis') == 'count' else 'mass',
        checked=False,
        passed=None,
        verdict='REFUSED',
        reasons=[
            'no metric scale (scale method none): sizes are in model units, so the '
            f'limits of class {spec["name"]} cannot be checked; capture a scale '
            'target or odometry'
        ],
    )


def sieve_table(grad: GradationCurve, unit: str) -> list[Sieve]:
    """Percent passing by mass and by count at the standard sizes round the measured range.

    Args:
        grad: The gradation curve.
        unit: ``"mm"`` or ``"in"``: which series of sizes.

    Returns:
        One row per size, from the last size below the smallest rock to the first at or above
        the largest.

    """
    sizes = np.asarray(grad.sizes, dtype=np.float64)
    if len(sizes) == 0:
        return []
    factor = LENGTH_UNITS[unit]
    series = np.asarray(_SIEVES[unit]) * factor
    first = max(int(np.searchsorted(series, sizes[0], side='left')) - 1, 0)
    last = min(int(np.searchsorted(series, sizes[-1], side='left')), len(series) - 1)
    rows = []
    for size in series[first : last + 1]:
        # Passing a sieve: every rock no larger than the opening (the curve's step function).
        k = int(np.searchsorted(sizes, size, side='right'))
        mass = float(grad.percent_passing_mass[k - 1]) if k else 0.0
        count = float(grad.percent_passing_count[k - 1]) if k else 0.0
        rows.append(Sieve(float(size), float(size / factor), mass, count))
    return rows


def rosin_rammler(grad: GradationCurve) -> RosinRammler | None:
    """Fit ``P(d) = 100 (1 - exp(-(d / d_c)^n))`` to the percent passing by mass.

    Least squares on ``ln(-ln(1 - P/100)) = n ln d - n ln d_c`` over the points strictly between
    0 and 100 %; None with fewer than three such points.
    """
    s = np.asarray(grad.sizes, dtype=np.float64)
    p = np.asarray(grad.percent_passing_mass, dtype=np.float64)
    use = (p > 0.0) & (p < 100.0) & (s > 0)
    if int(use.sum()) < 3 or np.ptp(np.log(s[use])) <= 0:
        return None
    x = np.log(s[use])
    y = np.log(-np.log(1.0 - p[use] / 100.0))
    n, b = np.polyfit(x, y, 1)
    if n <= 0:
        return None
    d_c = float(np.exp(-b / n))
    fitted = 100.0 * (1.0 - np.exp(-((s[use] / d_c) ** n)))
    return RosinRammler(
        d_c=d_c,
        n=float(n),
        rms_pct=float(np.sqrt(np.mean((fitted - p[use]) ** 2))),
        points=int(use.sum()),
    )
