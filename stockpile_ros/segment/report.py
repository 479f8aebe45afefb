"""The result folder.

report.json, segments.ply, rocks.csv, gradation.png, render.png, keyframe.png (when a keyframe
photo is at hand), index.html (self-contained: images inlined) and report.pdf (the same content,
printable, drawn with matplotlib so that no browser or system library is needed).
"""

from __future__ import annotations

import base64
import csv
import math
import os
import shutil
from collections.abc import Mapping
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from ..artefacts import ScaleRecord, save
from ..errors import StockpileError
from ..meshio import LabelledMesh, write_labelled_mesh
from ..result import ClassDecision, LimitRow, ProvenanceRecord, ProvenanceScale, Report, RockRecord
from .figures import find_keyframe, gradation_png, keyframe_png, render_png
from .measure import PARTLY_SEEN
from .pipeline import Analysis
from .provenance import Provenance
from .qa import LENGTH_UNITS, MASS_UNITS, ReportOptions

__all__ = ['ROCK_COLUMNS', 'page_context', 'write_pdf', 'write_result_folder']

ROCK_COLUMNS = (
    'id',
    'a',
    'b',
    'c',
    'esd',
    'volume',
    'mass',
    'visible_area',
    'visible_fraction',
    'fer',
    'sphericity',
    'confidence',
)

_SCALE_HOW = {
    'target': 'from the printed scale target seen in the keyframes',
    'odometry': 'from the fit of the Structure-from-Motion camera path to the odometry',
    'target+odometry': 'from the scale target and the odometry, combined by their uncertainties',
    'given': 'the mesh units given by the user (--units), no target or odometry',
    'input units': 'the units of the survey file (LAS/LAZ coordinates, taken as metres), no '
    'target or odometry',
    'sensor': 'the range sensor that measured the point cloud (PointCloud2, metres), no target',
}
# Volume display units: litres for metric pages, cubic feet for inch pages.
_VOLUME = {'mm': ('L', 1e-3), 'in': ('ft³', 0.0283168466)}


def _num(x: Any, digits: int = 3) -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return '-'
    return f'{x:.{digits}g}' if isinstance(x, float) else str(x)


def _scale_text(scale: ScaleRecord) -> str:
    method = scale.method
    if method == 'none':
        return 'none: no metric scale was found; every length is in model units (no verdict)'
    unc = scale.rel_uncertainty
    unc_text = (
        f'relative uncertainty {100 * unc:.2g} %' if unc is not None else 'uncertainty unknown'
    )
    how = _SCALE_HOW.get(method, method)
    return f'{method} ({how}): {_num(scale.metres_per_unit, 6)} m per model unit, {unc_text}'


def _reason(row: LimitRow, basis: str, length: Any, unit: str) -> str:
    label = f'{row.key.upper()} by {basis}'
    lo, hi = row.interval
    if row.value is None or lo is None:
        return row.reason
    bounds = ', '.join(
        f'{name} {length(bound)}'
        for name, bound in (('min', row.min), ('max', row.max))
        if bound is not None
    )
    verb = 'fails' if row.status == 'fail' else 'undecided'
    return (
        f'{label} {verb}: measured {length(row.value)} {unit}, interval '
        f'{length(lo)}-{length(hi)} {unit}, limits {bounds} {unit}'
    )


def _provenance(report: Report, provenance: Provenance) -> ProvenanceRecord:
    scale = report.scale
    return ProvenanceRecord(
        **asdict(provenance),
        keyframes_used=len(report.keyframes),
        scale=ProvenanceScale(scale.method, scale.rel_uncertainty, _scale_text(scale)),
    )


def page_context(
    report: Report,
    options: ReportOptions,
    images: Mapping[str, bytes],
    keyframe_note: str,
) -> dict[str, Any]:
    """Everything the page and the PDF show, formatted in the display units.

    Args:
        report: The report, ``provenance`` included.
        options: Display units and interval settings.
        images: PNG bytes by name (``gradation``, ``render``, optionally ``keyframe``).
        keyframe_note: Which keyframe is shown, or why none is.

    """
    metric = report.metric
    lu = options.length_unit if metric else 'model units'
    lf = LENGTH_UNITS[options.length_unit] if metric else 1.0
    mu, mf = options.mass_unit, MASS_UNITS[options.mass_unit]
    vu, vf = _VOLUME[options.length_unit] if metric else ('model units³', 1.0)
    digits = 4 if options.length_unit == 'mm' else 3

    def length(x: float | None) -> str:
        return '-' if x is None or not math.isfinite(x) else f'{x / lf:.{digits}g}'

    def interval(pair: list[float | None]) -> str:
        lo, hi = pair
        return f'{"<" if lo is None else length(lo)} - {length(hi)}' if hi is not None else '-'

    g = report.gradation
    spec = g.spec
    iv = g.intervals
    basis = spec.basis or 'mass'
    limits = [
        {
            'label': f'{row.key.upper()} by {basis}',
            'min': length(row.min),
            'max': length(row.max),
            'value': length(row.value),
            'interval': interval(row.interval),
            'margin': length(row.margin) if row.margin is not None else '-',
            'margin_pct': _num(100 * row.margin_rel, 2) if row.margin_rel is not None else '-',
            'status': row.status,
        }
        for row in spec.limits
    ]
    dsizes = [
        {'name': key.upper(), 'value': length(value), 'interval': interval(iv.mass[key])}
        for key, value in g.characteristic.items()
    ]
    dsizes += [
        {
            'name': name,
            'value': _num(value),
            'interval': '-' if pair[1] is None else f'{_num(pair[0])} - {_num(pair[1])}',
        }
        for name, value, pair in (('Cu', g.cu, iv.cu), ('Cc', g.cc, iv.cc))
    ]
    # The page states its reasons in the units of its tables (report.json keeps them in metres).
    reasons = [_reason(row, basis, length, lu) for row in spec.limits if row.status != 'pass']
    if spec.verdict == 'FAIL':
        reasons.sort(key=lambda text: 'fails' not in text)
    rr = g.rosin_rammler
    head = ['id', f'a [{lu}]', f'b [{lu}]', f'c [{lu}]', f'ESD [{lu}]', f'volume [{vu}]']
    head += [f'mass [{mu}]'] if metric else []
    head += ['visible %', 'a/c', 'sphericity', 'confidence']
    rows = []
    for r in report.rocks:
        low = r.visible_fraction < PARTLY_SEEN
        cells = [
            f'{r.id}{" !" if low else ""}',
            *(length(x) for x in (r.a, r.b, r.c, r.esd)),
            _num(r.volume / vf),
        ]
        cells += [_num(r.mass / mf if r.mass is not None else None)] if metric else []
        cells += [
            f'{100 * r.visible_fraction:.0f}',
            _num(r.fer, 2),
            _num(r.sphericity, 2),
            _num(r.confidence, 2),
        ]
        rows.append({'low': low, 'cells': cells})
    rock_note = (
        'a >= b >= c measured on the visible surface (lower bounds for partly hidden rocks); '
        'a/c is the flat-and-elongated ratio; volume and mass include the unseen side, completed '
        f'as report.json says (segmentation.measure). Rows marked ! were seen on under '
        f'{PARTLY_SEEN:.0%} of their surface.'
    )
    if not metric:
        rock_note += ' No metric scale: lengths in model units, no masses.'
    units_text = (
        f'lengths in {lu}, masses in {mu}, volumes in {vu} (report.json and rocks.csv: m, kg)'
        if metric
        else 'model (no metric scale): no metres, no kilograms'
    )
    total = g.total_mass
    return {
        'p': report.provenance,
        'spec': spec,
        'reasons': reasons if spec.checked else list(spec.reasons),
        'g': g,
        'verdict_class': spec.verdict.replace(' ', ''),
        'conf_pct': f'{iv.confidence:.0%}',
        'scale_unc': f'{100 * iv.scale_rel_uncertainty:.2g} %',
        'limits': limits,
        'dsizes': dsizes,
        'lu': lu,
        'units_text': units_text,
        'total_mass': f'{total / mf:.4g} {mu}' if metric and total is not None else '',
        'rr': None
        if rr is None
        else {
            'd_c': length(rr.d_c),
            'n': f'{rr.n:.2f}',
            'rms': f'{rr.rms_pct:.1f}',
            'points': rr.points,
        },
        'sieves': [
            {'size': f'{s.size_display:g}', 'mass': f'{s.mass:.1f}', 'count': f'{s.count:.1f}'}
            for s in g.sieves
        ],
        'sieve_note': (
            'Share of the measured rocks whose b is at most the size (the curve between rocks is '
            'a step); metric sizes: ISO 565 / ASTM E11 openings to 125 mm, then R10 gauge sizes.'
            if options.length_unit == 'mm'
            else 'Share of the measured rocks whose b is at most the size (the curve between '
            'rocks is a step); ASTM E11 inch designations to 5 in, then whole-inch sizes.'
        ),
        'images': {k: base64.b64encode(v).decode() for k, v in images.items()},
        'keyframe_note': keyframe_note,
        'partly_pct': f'{PARTLY_SEEN:.0%}',
        'rock_head': head,
        'rock_rows': rows,
        'rock_note': rock_note,
        'warnings': report.warnings,
        'frame_id': report.frame_id,
        'schema': report.schema,
    }


def _html(context: Mapping[str, Any]) -> str:
    import jinja2

    env = jinja2.Environment(
        loader=jinja2.PackageLoader('stockpile_ros.segment', 'templates'),
        autoescape=True,
        undefined=jinja2.StrictUndefined,
    )
    return env.get_template('report.html.j2').render(**context)


def _text_block(fig: Any, y: float, lines: list[str], size: float = 8.5) -> float:
    import textwrap

    for line in lines:
        for part in textwrap.wrap(line, 118) or ['']:
            fig.text(0.06, y, part, fontsize=size, va='top', family='DejaVu Sans')
            y -= 0.0145 * size / 8.5
    return y - 0.006


# Width of a DejaVu Sans Mono character over its size, the page [in] and its printable width [pt].
_MONO_ADVANCE = 0.602
_A4 = (8.27, 11.69)
_TABLE_WIDTH_PT = 0.88 * _A4[0] * 72


def _table(fig: Any, y: float, header: list[str], rows: list[list[str]], height: float) -> float:
    """Draw a table from ``y`` down over ``height`` (figure fraction); return the y under it.

    One line of monospaced text per row, the columns padded to their widest cell (the first
    left-aligned, the others right-aligned): a few artists a page where matplotlib's table drew
    a patch and a text per cell (18 of 25 s of a 429-rock report went to its tables).
    """
    from matplotlib.lines import Line2D

    lines = [header, *rows]
    widths = [max(len(str(row[k])) for row in lines) for k in range(len(header))]

    def line(row: list[str]) -> str:
        cells = [str(row[0]).ljust(widths[0])]
        cells += [str(c).rjust(w) for c, w in zip(row[1:], widths[1:], strict=True)]
        return '  '.join(cells)

    chars = sum(widths) + 2 * (len(widths) - 1)
    size = min(7.5 if len(header) < 9 else 6.5, _TABLE_WIDTH_PT / (_MONO_ADVANCE * chars))
    pitch = height / len(lines)
    for k, row in enumerate(lines):
        fig.text(0.06, y - k * pitch, line(row), fontsize=size, family='DejaVu Sans Mono',
                 weight='bold' if k == 0 else 'normal', va='top')  # fmt: skip
    rule = y - 0.92 * pitch
    fig.add_artist(Line2D([0.06, 0.94], [rule, rule], transform=fig.transFigure, lw=0.4))
    return y - height - 0.012


def write_pdf(path: Path, context: Mapping[str, Any], images: Mapping[str, bytes]) -> None:
    """Write the page's content as a printable A4 PDF (matplotlib's PdfPages)."""
    import io

    import matplotlib

    matplotlib.use('Agg')
    from matplotlib.backends.backend_pdf import PdfPages
    from matplotlib.figure import Figure
    from matplotlib.image import imread

    p: ProvenanceRecord = context['p']
    spec: ClassDecision = context['spec']
    with PdfPages(path) as pdf:
        fig = Figure(figsize=_A4)
        fig.text(
            0.06,
            0.965,
            f'Stockpile report{": " + p.pile if p.pile else ""}',
            fontsize=16,
            weight='bold',
            va='top',
        )
        changed = ', '.join(f'{k} = {v}' for k, v in p.parameters_changed.items())
        y = _text_block(
            fig,
            0.935,
            [
                f'Site: {p.site or "(not given)"}    Pile: {p.pile or "(not given)"}    '
                f'Operator: {p.operator or "(not given)"}',
                f'Created (UTC): {p.created}    Tool: stockpile_ros {p.tool_version}    '
                f'Keyframes used: {p.keyframes_used}',
                f'Input: {p.input_path}',
                f'sha256 {p.input_sha256 or "-"} ({p.fingerprint_method})',
                f'Scale: {p.scale.how}',
                f'Units: {context["units_text"]}',
                f'Parameters changed: {changed or "none (every parameter at its default)"}',
            ],
        )
        colour = {'PASS': 'green', 'FAIL': 'red'}.get(spec.verdict, '#b35900')
        title = spec.verdict + (f' - class {spec.class_name}' if spec.class_name else '')
        fig.text(0.06, y, title, fontsize=15, weight='bold', color=colour, va='top')
        y = _text_block(fig, y - 0.03, [f'- {r}' for r in context['reasons']])
        if spec.checked:
            y = _text_block(
                fig,
                y,
                [
                    f'Standard: {spec.standard}, edition {spec.edition}'
                    + (f' ({spec.note})' if spec.note else ''),
                    f'Limits on b by {spec.basis}, sizes in {context["lu"]}; intervals '
                    f'{context["conf_pct"]} (bootstrap over rocks with the scale uncertainty '
                    f'{context["scale_unc"]}).',
                ],
            )
            rows = [
                [
                    r['label'],
                    r['min'],
                    r['max'],
                    r['value'],
                    r['interval'],
                    r['margin'],
                    r['margin_pct'],
                    r['status'],
                ]
                for r in context['limits']
            ]
            y = _table(
                fig,
                y,
                ['limit', 'min', 'max', 'measured', 'interval', 'margin', 'margin %', 'status'],
                rows,
                0.02 * (len(rows) + 1),
            )
            y = _text_block(fig, y, [f'Class table caveat: {spec.caveat or "(none given)"}'])
        for w in context['warnings']:
            y = _text_block(fig, y, [f'Warning: {w}'], 7.5)
        ds = context['dsizes']
        y = _table(
            fig,
            y,
            ['by mass', *(d['name'] for d in ds)],
            [
                [f'value [{context["lu"]}]', *(d['value'] for d in ds)],
                # The interval's ends on two rows: one cell each is too narrow for both.
                [f'{context["conf_pct"]} low', *(d['interval'].split(' - ')[0] for d in ds)],
                [f'{context["conf_pct"]} high', *(d['interval'].split(' - ')[-1] for d in ds)],
            ],
            0.075,
        )
        rr = context['rr']
        if rr:
            y = _text_block(
                fig,
                y,
                [
                    f'Rosin-Rammler fit: d_c = {rr["d_c"]} {context["lu"]}, '
                    f'n = {rr["n"]}, RMS residual {rr["rms"]} %.'
                ],
            )
        grad = imread(io.BytesIO(images['gradation']), format='png')
        h = min(0.36, y - 0.1)
        if h > 0.15:
            ax = fig.add_axes((0.06, y - h, 0.88, h))
            ax.imshow(grad)
            ax.set_axis_off()
            y -= h + 0.01
        fig.text(
            0.06,
            0.05,
            'Checked by: ____________________   Date: ____________   '
            'Signature: ____________________',
            fontsize=9,
        )
        pdf.savefig(fig)
        fig = Figure(figsize=_A4)
        fig.text(
            0.06, 0.965, 'Segmented pile and keyframe photo', fontsize=13, weight='bold', va='top'
        )
        _text_block(
            fig,
            0.94,
            [
                f"Numbers are the table's rock ids; ! and orange outlines mark "
                f'rocks seen on under {context["partly_pct"]} of their surface.'
            ],
        )
        ax = fig.add_axes((0.06, 0.56, 0.88, 0.36))
        ax.imshow(imread(io.BytesIO(images['render']), format='png'))
        ax.set_axis_off()
        if 'keyframe' in images:
            ax = fig.add_axes((0.06, 0.15, 0.88, 0.36))
            ax.imshow(imread(io.BytesIO(images['keyframe']), format='png'))
            ax.set_axis_off()
            fig.text(0.06, 0.53, context['keyframe_note'], fontsize=8.5)
        else:
            fig.text(0.06, 0.53, f'No keyframe photo: {context["keyframe_note"]}.', fontsize=9)
        sieves = context['sieves']
        if sieves:
            _text_block(
                fig, 0.135, [f'Percent passing at standard sizes. {context["sieve_note"]}'], 7.5
            )
            _table(
                fig,
                0.11,
                [f'size [{context["lu"]}]', *(s['size'] for s in sieves)],
                [
                    ['by mass %', *(s['mass'] for s in sieves)],
                    ['by count %', *(s['count'] for s in sieves)],
                ],
                0.06,
            )
        pdf.savefig(fig)
        per_page = 48
        rocks = context['rock_rows']
        for start in range(0, max(len(rocks), 1), per_page):
            fig = Figure(figsize=_A4)
            fig.text(0.06, 0.965, 'Rocks', fontsize=13, weight='bold', va='top')
            y = _text_block(fig, 0.94, [context['rock_note']], 7.5)
            chunk = [r['cells'] for r in rocks[start : start + per_page]]
            if chunk:
                _table(fig, y, context['rock_head'], chunk, 0.0165 * (len(chunk) + 1))
            pdf.savefig(fig)


def _csv_values(rock: RockRecord) -> list[float | None]:
    """Return the values of the ``ROCK_COLUMNS`` after ``id``, in order."""
    return [rock.a, rock.b, rock.c, rock.esd, rock.volume, rock.mass, rock.visible_area,
            rock.visible_fraction, rock.fer, rock.sphericity, rock.confidence]  # fmt: skip


def _write_csv(path: Path, analysis: Analysis, report: Report) -> None:
    with path.open('w', newline='') as out_csv:
        writer = csv.writer(out_csv)
        writer.writerow(
            [*ROCK_COLUMNS[:1], 'x', 'y', 'z', *ROCK_COLUMNS[1:], 'faces', 'partly_seen', 'units']
        )
        faces = {r.id: r.faces for r in analysis.rocks}
        for r in report.rocks:
            values = ['' if x is None or not math.isfinite(x) else x for x in _csv_values(r)]
            writer.writerow(
                [
                    r.id,
                    *r.centroid,
                    *values,
                    faces[r.id],
                    int(r.visible_fraction < PARTLY_SEEN),
                    report.units,
                ]
            )


def write_result_folder(
    out: str | Path,
    analysis: Analysis,
    provenance: Provenance,
    options: ReportOptions | None = None,
    keyframes_dir: Path | None = None,
) -> dict[str, Path]:
    """Write the result folder of docs/formats.md and return the paths written.

    Sets ``analysis.report.provenance`` (so that what is published matches the files).
    The folder is written beside and renamed into place: it never holds half a result, nor a
    mix of this run's files and an earlier run's.

    Args:
        out: The result folder (created when missing).
        analysis: The analysis, its report included.
        provenance: Who, where, from what; filled by the caller.
        options: Display units (None: the defaults).
        keyframes_dir: The work folder's ``keyframes/``, for the keyframe photo; None: none shown.

    """
    opts = options or ReportOptions()
    final = Path(out)
    if final.is_dir() and any(final.iterdir()) and not (final / 'report.json').exists():
        # It is replaced whole: never a folder of someone else's files.
        raise StockpileError(f'{final} holds files but no result; choose an empty folder')
    final.parent.mkdir(parents=True, exist_ok=True)
    folder = final.with_name(f'.{final.name}.{os.getpid()}.tmp')
    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir()
    report = analysis.report
    report.provenance = _provenance(report, provenance)
    metric = report.metric
    paths = {
        name: folder / name
        for name in (
            'report.json',
            'segments.ply',
            'rocks.csv',
            'gradation.png',
            'render.png',
            'index.html',
            'report.pdf',
        )
    }
    save(report, paths['report.json'])
    labels = analysis.segmentation.labels
    write_labelled_mesh(
        paths['segments.ply'],
        LabelledMesh(analysis.vertices, analysis.faces, labels, analysis.colors),
    )
    _write_csv(paths['rocks.csv'], analysis, report)
    unit = opts.length_unit if metric else None
    images = {
        'gradation': gradation_png(report.gradation, unit),
        'render': render_png(analysis.vertices, analysis.faces, labels, report.rocks, unit),
    }
    centroids = np.asarray([r.centroid for r in report.rocks]).reshape(-1, 3)
    view, note = find_keyframe(keyframes_dir, report.keyframes, centroids)
    if view is not None:
        try:
            images['keyframe'] = keyframe_png(
                view, analysis.vertices, analysis.faces, labels, report.rocks
            )
            note = (
                f'Keyframe {view.file.name} (stamp {view.stamp_ns}), the one that sees most rocks'
            )
        except OSError as exc:
            note = str(exc)
    for name in ('gradation', 'render', 'keyframe'):
        if name in images:
            paths[f'{name}.png'] = folder / f'{name}.png'
            paths[f'{name}.png'].write_bytes(images[name])
    context = page_context(report, opts, images, note)
    paths['index.html'].write_text(_html(context))
    write_pdf(paths['report.pdf'], context, images)
    old = final.with_name(f'.{final.name}.{os.getpid()}.old')
    if final.exists():
        final.replace(old)
    folder.replace(final)
    shutil.rmtree(old, ignore_errors=True)
    return {name: final / path.name for name, path in paths.items()}
