"""Printable pages of the scale targets: each at its true size, its spec and a check line on it.

One page per target of a spec string (:func:`~stockpile_ros.recon.scale.parse_targets`), one per
marker for ``aruco:DICT:*:SIZE_M``. Every length on the page is the target's own, in metres: the
figure is the paper's size (inches = metres / 0.0254) and the target is drawn in page
coordinates, never scaled to fit. Cells are embedded as 1-pixel-a-cell images drawn without
resampling (edges exact at any printer resolution). Round the ink is white paper of at least one
marker cell (what a detector needs to find the black border), inside the sheet; ink and text stay
inside the printable area (``PRINT_MARGIN`` from each edge). Under the target: its spec, a check
line of ``CHECK_LINE`` with millimetre ticks and what to measure after printing. A target that does
not fit the paper either way round is refused with its size and the smallest paper that takes it.
"""

from __future__ import annotations

import textwrap
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.text import Text

from .errors import StockpileError
from .recon.scale import BarSpec, MarkerSpec, Target, TargetSpec, dictionary_code, parse_targets

__all__ = [
    'CHECK_LINE',
    'PAPERS',
    'PRINT_MARGIN',
    'Ink',
    'Page',
    'layout_pages',
    'write_pdf',
]

# Portrait width and height [m] (ISO 216 and the US sizes).
PAPERS = {
    'a5': (0.148, 0.210),
    'a4': (0.210, 0.297),
    'a3': (0.297, 0.420),
    'a2': (0.420, 0.594),
    'a1': (0.594, 0.841),
    'a0': (0.841, 1.189),
    'letter': (0.2159, 0.2794),
    'legal': (0.2159, 0.3556),
    'tabloid': (0.2794, 0.4318),
}
# Office printers leave 3-6 mm at each edge unprinted.
PRINT_MARGIN = 0.01
# Long enough that the 0.3 % of the default printed-size uncertainty is a readable 0.3 mm.
CHECK_LINE = 0.1
# Room under the target for the spec, the check line and three lines of instructions [m].
_INFO_HEIGHT = 0.04
_INFO_WIDTH = CHECK_LINE + 0.02
_POINT = 0.0254 / 72.0


@dataclass(frozen=True)
class Ink:
    """Cells of one grid, black where True, covering a rectangle of the target.

    Attributes:
        cells: Rows x columns, row 0 at the top.
        left: Left edge from the target's left [m].
        top: Top edge from the target's top [m], downwards.
        width: Width of the grid [m].
        height: Height of the grid [m].

    """

    cells: npt.NDArray[np.bool_]
    left: float
    top: float
    width: float
    height: float


@dataclass(frozen=True)
class Page:
    """One printable page.

    Attributes:
        paper: Paper name (a key of :data:`PAPERS`).
        size: Page width and height [m], as it lies (portrait or landscape).
        origin: Page position of the target's top-left corner [m], y up from the bottom edge.
        extent: Target width and height [m] (its ink).
        quiet: White kept round the ink [m].
        ink: What is printed black.
        spec: The spec string the scale code takes for this target.
        title: What the target is, in words, with its sizes.
        measure: What to measure on the print besides the check line.

    """

    paper: str
    size: tuple[float, float]
    origin: tuple[float, float]
    extent: tuple[float, float]
    quiet: float
    ink: tuple[Ink, ...]
    spec: str
    title: str
    measure: str


def _marker_cells(dictionary: str, marker_id: int) -> npt.NDArray[np.bool_]:
    code = cv2.aruco.getPredefinedDictionary(dictionary_code(dictionary, dictionary)[1])
    side = code.markerSize + 2
    return np.asarray(cv2.aruco.generateImageMarker(code, marker_id, side) < 128)


def _cell(dictionary: str, size: float) -> float:
    code = cv2.aruco.getPredefinedDictionary(dictionary_code(dictionary, dictionary)[1])
    return size / (code.markerSize + 2)


def _mm(length: float) -> str:
    return f'{1000 * length:.1f} mm'


def _marker(spec: MarkerSpec, marker_id: int, text: str) -> tuple[tuple[Ink, ...], str, str, str]:
    ink = (Ink(_marker_cells(spec.dictionary, marker_id), 0.0, 0.0, spec.size, spec.size),)
    which = f'marker id {marker_id}' if spec.marker_id is not None else f'id {marker_id} of a set'
    title = f'{spec.dictionary} {which}: black square {_mm(spec.size)}'
    return ink, text, title, f'the black square on both sides: {_mm(spec.size)}'


def _board(spec: TargetSpec) -> tuple[tuple[Ink, ...], str, str, str]:
    board = spec.board()
    width, height = spec.squares_x * spec.square_length, spec.squares_y * spec.square_length
    # Markers sit in the white squares; every other square is black.
    black = np.ones((spec.squares_y, spec.squares_x), dtype=bool)
    ink = []
    for marker_id, corners in zip(np.ravel(board.getIds()), board.getObjPoints(), strict=True):
        quad = np.asarray(corners, dtype=np.float64).reshape(4, 3)
        col, row = (int(v) for v in quad[:, :2].mean(axis=0) // spec.square_length)
        black[row, col] = False
        left, top = quad[:, 0].min(), quad[:, 1].min()
        cells = _marker_cells(spec.dictionary, int(marker_id))
        ink.append(Ink(cells, left, top, spec.marker_length, spec.marker_length))
    squares = Ink(black, 0.0, 0.0, width, height)
    title = (f'ChArUco board {spec.squares_x} x {spec.squares_y}: squares '
             f'{_mm(spec.square_length)}, markers {_mm(spec.marker_length)} '
             f'({spec.dictionary})')  # fmt: skip
    return (
        (squares, *ink),
        spec.text(),
        title,
        f'a row of squares: {spec.squares_x} x {_mm(spec.square_length)} = {_mm(width)}',
    )


def _bar(spec: BarSpec, marker_size: float) -> tuple[tuple[Ink, ...], str, str, str]:
    gap = spec.distance - marker_size
    if gap < 2 * _cell(spec.dictionary, marker_size):
        raise StockpileError(
            f'target {spec.text()}: markers of {_mm(marker_size)} leave {_mm(gap)} between them '
            'where each needs a cell of white round it; give a smaller --bar-marker'
        )
    ink = (
        Ink(_marker_cells(spec.dictionary, spec.first), 0.0, 0.0, marker_size, marker_size),
        Ink(_marker_cells(spec.dictionary, spec.second), spec.distance, 0.0, marker_size,
            marker_size),
    )  # fmt: skip
    title = (f'scale bar: {spec.dictionary} ids {spec.first} and {spec.second}, centres '
             f'{_mm(spec.distance)} apart, markers {_mm(marker_size)}')  # fmt: skip
    # The two squares are the same size: edge to like edge is centre to centre.
    measure = f'the left edges of the two black squares: {_mm(spec.distance)} apart'
    return ink, spec.text(), title, measure


def _fits(paper: tuple[float, float], extent: tuple[float, float], quiet: float) -> bool:
    """Whether the ink, its white, and the text and check line under it fit the page."""
    width, height = paper
    # The white may reach into the unprinted margin (it is paper), the ink may not.
    side = max(PRINT_MARGIN, quiet)
    return (
        extent[0] + 2 * side <= width
        and extent[1] + side + quiet + _INFO_HEIGHT + PRINT_MARGIN <= height
        and width >= _INFO_WIDTH + 2 * PRINT_MARGIN
    )


def _place(
    name: str, extent: tuple[float, float], quiet: float, spec: str
) -> tuple[tuple[float, float], tuple[float, float]]:
    """Page size as it lies and the target's top-left corner on it; refuses what cannot fit."""
    width, height = PAPERS[name]
    for size in ((width, height), (height, width)):
        if _fits(size, extent, quiet):
            left = (size[0] - extent[0]) / 2
            top = size[1] - max(PRINT_MARGIN, quiet)
            return size, (left, top)
    takes = [p for p in sorted(PAPERS, key=lambda p: PAPERS[p][0] * PAPERS[p][1])
             if any(_fits(s, extent, quiet) for s in (PAPERS[p], PAPERS[p][::-1]))]  # fmt: skip
    hint = f'the smallest paper that takes it is {takes[0].upper()}' if takes else 'no paper here'
    raise StockpileError(
        f'target {spec}: it is {_mm(extent[0])} x {_mm(extent[1])} of ink with {_mm(quiet)} of '
        f'white round it and {_mm(_INFO_HEIGHT)} under it for the check line; it does not fit '
        f'{name.upper()} ({_mm(width)} x {_mm(height)}, {_mm(PRINT_MARGIN)} unprinted at each '
        f'edge) either way round: {hint} (--paper), or print a smaller target'
    )


def layout_pages(
    text: str, paper: str = 'a4', *, ids: Sequence[int] = (0, 1), bar_marker: float | None = None
) -> list[Page]:
    """Pages of every target of a spec string.

    Args:
        text: The spec string (as ``recon.target`` takes it).
        paper: A key of :data:`PAPERS`.
        ids: The markers printed for ``aruco:DICT:*:SIZE_M``, one page each.
        bar_marker: Black-square edge of a scale bar's two markers [m]; None: a quarter of the
            bar's length.

    Raises:
        StockpileError: The spec does not parse, names no target, an id is past its dictionary,
            or a target does not fit the paper (with the reason and the paper that would do).

    """
    if paper not in PAPERS:
        raise StockpileError(f'paper {paper!r}: one of {", ".join(PAPERS)}')
    targets = parse_targets(text)
    if not targets:
        raise StockpileError('no target to print: give a spec, e.g. aruco:DICT_4X4_50:0:0.15')
    pages = []
    for target in targets:
        for drawn in _drawings(target, text, ids, bar_marker):
            ink, spec, title, measure, quiet = drawn
            extent = (max(i.left + i.width for i in ink), max(i.top + i.height for i in ink))
            size, origin = _place(paper, extent, quiet, spec)
            pages.append(Page(paper, size, origin, extent, quiet, ink, spec, title, measure))
    return pages


_Drawing = tuple[tuple[Ink, ...], str, str, str, float]


def _drawings(
    target: Target, text: str, ids: Sequence[int], bar_marker: float | None
) -> list[_Drawing]:
    if isinstance(target, TargetSpec):
        ink, spec, title, measure = _board(target)
        # The outer markers have their square's white margin; a cell more is asked only where
        # that margin is under a cell.
        cell = _cell(target.dictionary, target.marker_length)
        margin = (target.square_length - target.marker_length) / 2
        return [(ink, spec, title, measure, max(0.0, cell - margin))]
    if isinstance(target, BarSpec):
        size = target.distance / 4 if bar_marker is None else bar_marker
        ink, spec, title, measure = _bar(target, size)
        return [(ink, spec, title, measure, _cell(target.dictionary, size))]
    chosen = [target.marker_id] if target.marker_id is not None else list(ids)
    limit = len(
        cv2.aruco.getPredefinedDictionary(dictionary_code(target.dictionary, text)[1]).bytesList
    )
    out = []
    for marker_id in chosen:
        if not 0 <= marker_id < limit:
            raise StockpileError(f'marker id {marker_id}: {target.dictionary} has ids 0 to '
                                 f'{limit - 1}')  # fmt: skip
        ink, spec, title, measure = _marker(target, marker_id, target.text())
        out.append((ink, spec, title, measure, _cell(target.dictionary, target.size)))
    return out


def _instructions(page: Page, tolerance: float) -> list[str]:
    allowed = CHECK_LINE * tolerance
    return [
        f'Print at 100 % (actual size, no "fit to page"). Measure the line: {_mm(CHECK_LINE)}, '
        f'within {1000 * allowed:.1f} mm ({100 * tolerance:.1f} %).',
        f'Then measure {page.measure}. If it is off by more than {100 * tolerance:.1f} %, give '
        'the measured size in the spec.',
        f'Keep {_mm(max(page.quiet, PRINT_MARGIN))} of white round the ink; glue flat on a '
        'rigid board.',
    ]


def write_pdf(pages: Sequence[Page], path: Path, *, tolerance: float = 0.003) -> None:
    """Write the pages into one PDF at true size.

    Args:
        pages: From :func:`layout_pages`.
        path: The PDF to write.
        tolerance: Relative error a print may have (``recon.target_size_uncertainty``).

    Raises:
        StockpileError: Text would run off the printable area or into the target's white.

    """
    import matplotlib
    from matplotlib.backends.backend_pdf import PdfPages

    figures = [_draw(page, tolerance) for page in pages]
    # TrueType fonts keep the spec a text a reader can select and search.
    metadata = {'Title': ', '.join(dict.fromkeys(p.spec for p in pages)),
                'Subject': 'stockpile_ros scale targets: print at 100 %'}  # fmt: skip
    with matplotlib.rc_context({'pdf.fonttype': 42}), PdfPages(path, metadata=metadata) as pdf:
        for fig in figures:
            pdf.savefig(fig)


def _draw(page: Page, tolerance: float) -> Figure:
    """One page as a figure of the paper's size, every coordinate in metres from bottom-left."""
    width, height = page.size
    fig = Figure(figsize=(width / 0.0254, height / 0.0254))
    FigureCanvasAgg(fig)
    ax = fig.add_axes((0.0, 0.0, 1.0, 1.0))
    ax.set_axis_off()
    left, top = page.origin
    for ink in page.ink:
        # One pixel a cell, not resampled: viewers and printers draw the cells' edges exactly.
        ax.imshow(
            ~ink.cells, cmap='gray', vmin=0, vmax=1, interpolation='none', aspect='auto',
            extent=(left + ink.left, left + ink.left + ink.width,
                    top - ink.top - ink.height, top - ink.top),
        )  # fmt: skip
    # imshow sets the limits to its image: the axes are the page, in metres.
    ax.set_xlim(0.0, width)
    ax.set_ylim(0.0, height)
    room = top - page.extent[1] - page.quiet - 0.003
    x0 = PRINT_MARGIN
    texts = [
        ax.text(x0, room, page.spec, fontsize=11, weight='bold', va='top'),
        ax.text(x0, room - 0.0055, page.title, fontsize=7, va='top'),
    ]
    line = room - 0.016
    ax.plot([x0, x0 + CHECK_LINE], [line, line], color='black', linewidth=0.5,
            solid_capstyle='butt')  # fmt: skip
    for mm in range(round(CHECK_LINE * 1000) + 1):
        tick = 0.003 if mm % 10 == 0 else 0.0015
        ax.plot([x0 + mm / 1000] * 2, [line, line + tick], color='black', linewidth=0.3,
                solid_capstyle='butt')  # fmt: skip
    texts.append(ax.text(x0 + CHECK_LINE + 0.002, line, _mm(CHECK_LINE), fontsize=7,
                         va='center'))  # fmt: skip
    # A 6 pt character is under 1.3 mm wide: wrapped to the printable width.
    columns = int((width - 2 * PRINT_MARGIN) / 0.0013)
    lines = [w for words in _instructions(page, tolerance) for w in textwrap.wrap(words, columns)]
    for k, words in enumerate(lines):
        texts.append(ax.text(x0, line - 0.003 - 0.0033 * k, words, fontsize=6, va='top'))
    _check_text(fig, texts, page, room)
    return fig


def _check_text(fig: Figure, texts: list[Text], page: Page, room: float) -> None:
    """Refuse a page whose text runs off the printable area or up into the target's white."""
    renderer = fig.canvas.get_renderer()  # type: ignore[attr-defined]
    for text in texts:
        box = text.get_window_extent(renderer)
        right, bottom, top = (v / fig.dpi * 0.0254 for v in (box.x1, box.y0, box.y1))
        if right > page.size[0] - PRINT_MARGIN or bottom < PRINT_MARGIN or top > room + 0.001:
            raise StockpileError(
                f'target {page.spec}: its text does not fit under it on {page.paper.upper()}; '
                'use a larger --paper'
            )
