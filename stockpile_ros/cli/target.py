"""``stockpile target``: a PDF of the scale targets of a spec, at true size, to print."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..recon.options import ReconOptions
from ..target_pages import CHECK_LINE, PAPERS, layout_pages, write_pdf

__all__ = ['DESCRIPTION', 'add_arguments', 'run']

DESCRIPTION = f"""\
Write a PDF with every target of SPEC (the recon.target spec) at its true size, one a page:
aruco:DICT:ID:SIZE_M, aruco:DICT:*:SIZE_M (one page per id of --ids), apriltag:FAMILY:ID:SIZE_M,
bar:DICT:ID1:ID2:DIST_M (two markers of --bar-marker, centres DIST_M apart) and
charuco:SXxSY:SQUARE_M:MARKER_M[:DICT]. Each page carries the spec to give to
--set recon.target=..., a {1000 * CHECK_LINE:.0f} mm check line and what to measure after printing
(docs/field_capture.md). Print at 100 %, never "fit to page". A target that does not fit the paper
either way round is refused, with the smallest paper that would take it.

examples:
  stockpile target --out marker.pdf aruco:DICT_4X4_50:0:0.15
  stockpile target --out markers.pdf --ids 0,1,2,3 'aruco:DICT_4X4_50:*:0.15'
  stockpile target --out board.pdf --paper a2 charuco:5x4:0.08:0.06:DICT_4X4_50
"""


def _ids(text: str) -> tuple[int, ...]:
    try:
        return tuple(int(part) for part in text.split(','))
    except ValueError:
        raise argparse.ArgumentTypeError(f'{text!r}: marker ids joined by commas') from None


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Declare the arguments of ``stockpile target``."""
    parser.add_argument('spec', metavar='SPEC', help='target spec, as recon.target takes it')
    parser.add_argument('--out', type=Path, required=True, help='the PDF to write')
    parser.add_argument('--paper', choices=list(PAPERS), default='a4',
                        help='paper size (default %(default)s), portrait or landscape')  # fmt: skip
    parser.add_argument('--ids', type=_ids, default=(0, 1), metavar='ID,ID,...',
                        help='markers printed for an aruco:DICT:*:SIZE_M spec, one page each '
                             '(default 0,1)')  # fmt: skip
    parser.add_argument('--bar-marker', type=float, metavar='M',
                        help='black-square edge of a scale bar\'s markers [m] '
                             '(default a quarter of the bar)')  # fmt: skip


def run(args: argparse.Namespace) -> int:
    """Write the PDF and say what is on each page; 0 on success."""
    pages = layout_pages(args.spec, args.paper, ids=args.ids, bar_marker=args.bar_marker)
    tolerance = ReconOptions().target_size_uncertainty
    write_pdf(pages, args.out, tolerance=tolerance)
    for number, page in enumerate(pages, start=1):
        width, height = (1000 * v for v in page.size)
        print(f'page {number} ({page.paper.upper()}, {width:.0f} x {height:.0f} mm): {page.title}; '
              f'spec {page.spec}')  # fmt: skip
    print(f'{args.out}: print at 100 % (actual size); measure the {1000 * CHECK_LINE:.0f} mm check '
          f'line and the target: within {100 * tolerance:.1f} %, or give the measured size in the '
          'spec')  # fmt: skip
    return 0
