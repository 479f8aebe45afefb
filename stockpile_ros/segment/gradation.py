"""Gradation of a pile from per-rock sizes and masses, and the riprap class tables.

Usable on its own (for instance on the simulator's truth): :func:`gradation` takes plain arrays.
The check against a class, with intervals, is :func:`~.qa.decide`'s.

Percent passing at size ``s`` is the share (by count, or by mass) of rocks whose size is at most
``s``, evaluated at every rock's size. Characteristic sizes ``D_p`` are read off the mass curve by
linear interpolation in ``log(size)`` (the usual semi-log gradation plot); ``D_p`` is ``None`` when
``p`` is below the first point of the curve (the smallest rock alone holds more than ``p`` % of the
mass), since the sample says nothing about smaller sizes. ``D100`` is the largest size.
``Cu = D60 / D10``, ``Cc = D30^2 / (D10 D60)``, ``None`` when a factor is undefined.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import yaml

from ..errors import StockpileError
from ..result import GradationCurve

__all__ = ['PERCENTS', 'gradation', 'load_class_table', 'percent_size']

#: The characteristic sizes reported, as percent passing by mass.
PERCENTS = (10, 15, 30, 50, 60, 85, 100)

_DEFAULT_TABLE = Path(__file__).resolve().parents[2] / 'config' / 'riprap_classes.yaml'


def percent_size(sizes: npt.ArrayLike, passing: npt.ArrayLike, percent: float) -> float | None:
    """Size at which the curve ``(sizes, passing)`` reaches ``percent``, interpolated in log size.

    Args:
        sizes: Sizes in ascending order (> 0).
        passing: Percent passing at each size, non-decreasing, last value 100.
        percent: The percent sought.

    Returns:
        The size, or None below the first point of the curve or for an empty curve.

    """
    s = np.asarray(sizes, dtype=np.float64)
    p = np.asarray(passing, dtype=np.float64)
    if len(s) == 0 or percent < p[0] - 1e-9:
        return None
    if percent >= p[-1]:
        return float(s[-1])
    # Equal passing values (zero-mass rocks) would make the inverse ambiguous: keep the first.
    keep = np.ones(len(p), dtype=bool)
    keep[1:] = p[1:] > p[:-1]
    s, p = s[keep], p[keep]
    return float(np.exp(np.interp(percent, p, np.log(s))))


def _none_if_nan(x: float | None) -> float | None:
    return None if x is None or not math.isfinite(x) else float(x)


def gradation(
    sizes: npt.ArrayLike, masses: npt.ArrayLike, size_measure: str = 'b'
) -> GradationCurve:
    """Return the gradation curve of a set of rocks (docs/formats.md).

    Args:
        sizes: Size of each rock [m] (``size_measure``, normally the intermediate dimension b).
        masses: Mass of each rock [kg].
        size_measure: Name of the size used, recorded in the curve.

    """
    s = np.asarray(sizes, dtype=np.float64).ravel()
    m = np.asarray(masses, dtype=np.float64).ravel()
    if s.shape != m.shape:
        raise ValueError(f'{len(s)} sizes for {len(m)} masses')
    ok = np.isfinite(s) & np.isfinite(m) & (s > 0) & (m >= 0)
    s, m = s[ok], m[ok]
    order = np.argsort(s, kind='stable')
    s, m = s[order], m[order]
    n = len(s)
    total = float(m.sum())
    # Rocks of equal size pass the same sieve: evaluate each at the last of its ties.
    last = np.searchsorted(s, s, side='right') - 1
    by_count = 100.0 * (last + 1) / n if n else np.zeros(0)
    by_mass = 100.0 * np.cumsum(m)[last] / total if total > 0 else np.zeros(n)
    ds = {pct: percent_size(s, by_mass, pct) if total > 0 else None for pct in PERCENTS}
    d10, d30, d60 = ds[10], ds[30], ds[60]
    return GradationCurve(
        size_measure=size_measure,
        sizes=s.tolist(),
        percent_passing_count=np.asarray(by_count).tolist(),
        percent_passing_mass=np.asarray(by_mass).tolist(),
        d10=d10,
        d15=ds[15],
        d30=d30,
        d50=ds[50],
        d60=d60,
        d85=ds[85],
        d100=ds[100],
        cu=_none_if_nan(d60 / d10) if d10 and d60 else None,
        cc=_none_if_nan(d30 * d30 / (d10 * d60)) if d10 and d30 and d60 else None,
        rock_count=n,
        total_mass=total,
    )


def load_class_table(path: str | Path | None = None) -> dict[str, Any]:
    """Read the riprap class table (``config/riprap_classes.yaml`` by default), sizes in metres.

    Each class entry carries the table's ``standard``, ``edition`` and ``caveat`` ('' if absent).

    Raises:
        StockpileError: The file is missing or malformed.

    """
    file = Path(path) if path is not None else _DEFAULT_TABLE
    try:
        data = yaml.safe_load(file.read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise StockpileError(f'cannot read class table {file}: {exc}') from exc
    if not isinstance(data, dict) or not isinstance(data.get('classes'), dict):
        raise StockpileError(f'{file}: expected a mapping with a "classes" mapping')
    factor = {'m': 1.0, 'mm': 1e-3, 'in': 0.0254}.get(str(data.get('units', 'm')))
    if factor is None:
        raise StockpileError(f'{file}: units must be m, mm or in')
    basis = str(data.get('basis', 'mass'))
    if basis not in ('mass', 'count'):
        raise StockpileError(f'{file}: basis must be mass or count')
    # Every verdict is printed with the standard it was checked against and the table's caveat.
    edition = {key: str(data.get(key, '')) for key in ('standard', 'edition', 'caveat')}
    classes: dict[str, Any] = {}
    for name, entry in data['classes'].items():
        limits: dict[str, list[float | None]] = {}
        for key, pair in (entry.get('limits') or {}).items():
            if (
                key not in {f'd{p}' for p in PERCENTS}
                or not isinstance(pair, list)
                or len(pair) != 2
            ):
                raise StockpileError(f'{file}: class {name}: bad limit {key}: {pair}')
            limits[key] = [None if x is None else float(x) * factor for x in pair]
        classes[str(name)] = {
            'name': str(name),
            'basis': basis,
            'limits': limits,
            'note': entry.get('note', ''),
            **edition,
        }
    return {
        'source': data.get('source', ''),
        **edition,
        'basis': basis,
        'size_measure': data.get('size_measure', 'b'),
        'classes': classes,
    }
