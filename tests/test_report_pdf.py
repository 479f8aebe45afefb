"""The printable report: every rock of the result folder's table on the PDF's rock pages."""

from __future__ import annotations

import csv
import math

import pypdfium2 as pdfium
from segment_fixtures import small_pile_file

from stockpile_ros.cli import main


def _page_lines(path) -> list[list[str]]:
    pdf = pdfium.PdfDocument(path)
    try:
        return [page.get_textpage().get_text_range().splitlines() for page in pdf]
    finally:
        pdf.close()


def test_the_pdf_lists_every_rock_in_aligned_columns(tmp_path) -> None:
    mesh_path = small_pile_file(tmp_path)
    out = tmp_path / 'result'
    assert main(['segment', str(mesh_path), '--out', str(out), '--units', 'm']) == 0
    with (out / 'rocks.csv').open() as handle:
        rocks = list(csv.DictReader(handle))
    pages = _page_lines(out / 'report.pdf')
    assert len(pages) == 2 + math.ceil(len(rocks) / 48), [p[:1] for p in pages]
    table = [line.split() for page in pages[2:] for line in page]
    assert ['id', 'a', '[mm]', 'b', '[mm]', 'c', '[mm]'] in [row[:7] for row in table]
    found = {row[0]: row for row in table if row and row[0].isdigit()}
    assert sorted(found, key=int) == sorted((r['id'] for r in rocks), key=int)
    for rock in rocks:
        cells = [c for c in found[rock['id']] if c != '!']
        # a, b and c in millimetres, to the table's four significant digits.
        for cell, key in zip(cells[1:4], 'abc', strict=True):
            assert float(cell) == float(f'{1000 * float(rock[key]):.4g}'), (cells, key)
