"""The result folder.

report.json, segments.ply, rocks.csv, gradation.png, render.png, index.html.
"""

from __future__ import annotations

import base64
import csv
import html
import io
import json
from pathlib import Path
from typing import Any

import numpy as np

from ..meshio import LabelledMesh, write_labelled_mesh
from .pipeline import Analysis
from .render import render_labels

__all__ = ['ROCK_COLUMNS', 'plot_gradation', 'write_result_folder']

ROCK_COLUMNS = ('id', 'a', 'b', 'c', 'esd', 'volume', 'mass', 'visible_area', 'visible_fraction',
                'fer', 'sphericity', 'confidence')  # fmt: skip


def plot_gradation(grad: dict[str, Any], spec: dict[str, Any] | None = None) -> bytes:
    """PNG of the gradation curves (percent passing by mass and by count against size, log axis)."""
    import matplotlib

    matplotlib.use('Agg')
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7, 4.5), dpi=110)
    ax = fig.add_subplot(1, 1, 1)
    sizes = np.asarray(grad['sizes'], dtype=np.float64)
    if len(sizes):
        ax.step(sizes, grad['percent_passing_mass'], where='post', color='tab:blue', alpha=0.35)
        ax.plot(sizes, grad['percent_passing_mass'], 'o-', color='tab:blue', label='by mass')
        ax.plot(
            sizes, grad['percent_passing_count'], 's--', color='tab:gray', ms=3, label='by count'
        )
        ax.set_xscale('log')
    for pct in (15, 50, 85):
        d = grad.get(f'd{pct}')
        if d:
            ax.plot([d], [pct], 'kx')
            ax.annotate(f'D{pct} {d:.3f} m', (d, pct), textcoords='offset points', xytext=(6, -10))
    if spec:
        for key, (lo, hi) in spec.get('limits', {}).items():
            pct = int(key[1:])
            xs = [x for x in (lo, hi) if x is not None]
            if xs:
                ax.plot(xs, [pct] * len(xs), '|-', color='tab:red', lw=2, ms=12)
        ax.plot([], [], '|-', color='tab:red', label=f'class {spec["name"]} limits')
    ax.set_xlabel(f'size {grad.get("size_measure", "b")} [m]')
    ax.set_ylabel('percent passing [%]')
    ax.set_ylim(0, 102)
    ax.grid(True, which='both', alpha=0.3)
    ax.legend(loc='lower right')
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format='png')
    return buf.getvalue()


def _png(image: np.ndarray) -> bytes:
    from matplotlib.image import imsave

    buf = io.BytesIO()
    imsave(buf, image, format='png')
    return buf.getvalue()


def _fmt(x: Any, digits: int = 3) -> str:
    if x is None:
        return '-'
    if isinstance(x, float):
        return f'{x:.{digits}f}'
    return str(x)


def _html(report: dict[str, Any], grad_png: bytes, view_png: bytes) -> str:
    g = report['gradation']
    spec = g['spec']
    if not spec['checked']:
        verdict = 'not checked (no class given)'
    elif spec['passed']:
        verdict = f'<b style="color:green">PASS</b> class {html.escape(str(spec["class"]))}'
    else:
        reasons = ''.join(f'<li>{html.escape(r)}</li>' for r in spec['reasons'])
        name = html.escape(str(spec['class']))
        verdict = f'<b style="color:red">FAIL</b> class {name}<ul>{reasons}</ul>'
    rows = ''.join(
        '<tr>' + ''.join(f'<td>{_fmt(r.get(c))}</td>' for c in ROCK_COLUMNS) + '</tr>'
        for r in report['rocks']
    )
    head = ''.join(f'<th>{c}</th>' for c in ROCK_COLUMNS)
    ds = ', '.join(f'D{p} = {_fmt(g.get(f"d{p}"))} m' for p in (10, 15, 30, 50, 60, 85, 100))
    scale = report['scale']
    seg = report['segmentation']
    warnings = ''.join(
        f'<p style="color:#b35900"><b>Warning:</b> {html.escape(w)}</p>'
        for w in report.get('warnings', [])
    )
    b64 = base64.b64encode
    return f"""<!DOCTYPE html>
<html><head><meta charset="utf-8"><title>Stockpile report</title>
<style>body{{font-family:sans-serif;margin:2em}} table{{border-collapse:collapse}}
td,th{{border:1px solid #ccc;padding:2px 6px;text-align:right}} img{{max-width:100%}}</style></head>
<body><h1>Stockpile report</h1>
<p>{g['rock_count']} rocks measured, total mass {_fmt(g['total_mass'], 1)} kg (visible rocks only).
Segmentation mode <code>{html.escape(str(seg.get('mode')))}</code>, threshold
{seg.get('threshold')},
{seg.get('segments')} segments. Scale: {html.escape(str(scale.get('method')))}
(relative uncertainty {_fmt(scale.get('rel_uncertainty'))}). Frame
<code>{html.escape(report['frame_id'])}</code>,
units m, kg.</p>
<p>Specification: {verdict}</p>
{warnings}
<p>{ds}; Cu = {_fmt(g.get('cu'), 2)}, Cc = {_fmt(g.get('cc'), 2)}.</p>
<h2>Segmented pile</h2>
<img alt="segmented pile" src="data:image/png;base64,{b64(view_png).decode()}">
<h2>Gradation</h2>
<img alt="gradation curve" src="data:image/png;base64,{b64(grad_png).decode()}">
<h2>Rocks</h2><p>Sizes in m, volume in m&sup3;, mass in kg, area in m&sup2;.
a &ge; b &ge; c measured on the visible surface (lower bounds for partly hidden rocks); fer = a / c;
the unseen side, for volume and mass, completed as documented in report.json
(segmentation.measure).</p>
<table><tr>{head}</tr>{rows}</table></body></html>
"""


def write_result_folder(
    out: str | Path, analysis: Analysis, spec: dict[str, Any] | None = None
) -> dict[str, Path]:
    """Write the result folder of docs/formats.md and return the paths written."""
    folder = Path(out)
    folder.mkdir(parents=True, exist_ok=True)
    names = (
        'report.json',
        'segments.ply',
        'rocks.csv',
        'gradation.png',
        'render.png',
        'index.html',
    )
    paths = {name: folder / name for name in names}
    report = analysis.report
    paths['report.json'].write_text(json.dumps(report, indent=1, allow_nan=False))
    write_labelled_mesh(
        paths['segments.ply'],
        LabelledMesh(
            analysis.vertices, analysis.faces, analysis.segmentation.labels, analysis.colors
        ),
    )
    with paths['rocks.csv'].open('w', newline='') as out_csv:
        writer = csv.writer(out_csv)
        writer.writerow([*ROCK_COLUMNS[:1], 'x', 'y', 'z', *ROCK_COLUMNS[1:], 'faces'])
        faces = {r.id: r.faces for r in analysis.rocks}
        for r in report['rocks']:
            writer.writerow(
                [r['id'], *r['centroid'], *(r[c] for c in ROCK_COLUMNS[1:]), faces[r['id']]]
            )
    grad_png = plot_gradation(report['gradation'], spec)
    paths['gradation.png'].write_bytes(grad_png)
    view = render_labels(analysis.vertices, analysis.faces, analysis.segmentation.labels)
    view_png = _png(view)
    paths['render.png'].write_bytes(view_png)
    paths['index.html'].write_text(_html(report, grad_png, view_png))
    return paths
