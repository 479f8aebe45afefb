"""Printed targets: the PDF's pages at true size, markers found at their size, the spec readable."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pypdfium2 as pdfium
import pypdfium2.raw as pdfium_raw
import pytest

from stockpile_ros.cli import main
from stockpile_ros.errors import StockpileError
from stockpile_ros.recon.scale import (
    BarSpec,
    MarkerSpec,
    TargetSpec,
    detect_charuco,
    detect_markers,
    parse_targets,
)
from stockpile_ros.target_pages import CHECK_LINE, PAPERS, layout_pages, write_pdf

DPI = 200.0
PX_PER_M = DPI / 0.0254
# The rasteriser puts an image's edges on its pixel grid: a drawn length comes out within a pixel
# or two of the PDF's; the PDF's own geometry is checked exactly (_images).
RASTER = 2.0 / PX_PER_M


def _pages(path: Path) -> list[tuple[tuple[float, float], np.ndarray, str]]:
    """Per page: its size [m], a grey raster at DPI and its text."""
    out = []
    for page in pdfium.PdfDocument(str(path)):
        width, height = page.get_size()
        grey = np.asarray(page.render(scale=DPI / 72, grayscale=True).to_numpy())
        grey = grey[..., 0] if grey.ndim == 3 else grey
        text = page.get_textpage().get_text_range()
        out.append(((width / 72 * 0.0254, height / 72 * 0.0254), grey.copy(), text))
    return out


def _images(path: Path) -> list[np.ndarray]:
    """Bounds (left, bottom, right, top) [m] of the images of the first page, in drawing order."""
    page = pdfium.PdfDocument(str(path))[0]
    objects = page.get_objects(filter=[pdfium_raw.FPDF_PAGEOBJ_IMAGE])
    return [np.array(obj.get_bounds()) / 72 * 0.0254 for obj in objects]


def _edge(quad: np.ndarray) -> float:
    """Mean of a detected square's four edges [m]."""
    return float(np.mean(np.linalg.norm(np.roll(quad, -1, axis=0) - quad, axis=1))) / PX_PER_M


def _write(tmp_path: Path, spec: str, paper: str = 'a4', **kw: object) -> Path:
    path = tmp_path / 'target.pdf'
    write_pdf(layout_pages(spec, paper, **kw), path)  # type: ignore[arg-type]
    return path


@pytest.mark.parametrize(
    ('spec', 'paper'),
    [('aruco:DICT_4X4_50:7:0.15', 'a4'), ('apriltag:36h11:5:0.12', 'letter'),
     ('aruco:DICT_6X6_250:200:0.05', 'a5')],
)  # fmt: skip
def test_a_marker_prints_at_its_size_with_its_spec(tmp_path: Path, spec: str, paper: str) -> None:
    path = _write(tmp_path, spec, paper)
    ((size, grey, text),) = _pages(path)
    assert sorted(size) == pytest.approx(sorted(PAPERS[paper]), abs=1e-5)
    (target,) = parse_targets(spec)
    assert isinstance(target, MarkerSpec)
    ((left, bottom, right, top),) = _images(path)
    assert (right - left, top - bottom) == pytest.approx((target.size, target.size), abs=1e-6)
    found = detect_markers(grey, [target.dictionary])
    assert list(found) == [(target.dictionary, target.marker_id)]
    assert _edge(found[(target.dictionary, target.marker_id)]) == pytest.approx(
        target.size, abs=RASTER
    )
    # The spec on the page is what the scale code takes, and names this very target.
    first = text.splitlines()[0].strip()
    assert parse_targets(first) == (target,)
    assert f'{1000 * CHECK_LINE:.1f} mm' in text and '100 %' in text


def test_every_marker_of_a_set_gets_a_page_and_the_set_spec(tmp_path: Path) -> None:
    pages = _pages(_write(tmp_path, 'aruco:DICT_4X4_50:*:0.1', ids=(3, 9, 11)))
    assert len(pages) == 3
    for marker, (_, grey, text) in zip((3, 9, 11), pages, strict=True):
        found = detect_markers(grey, ['DICT_4X4_50'])
        assert list(found) == [('DICT_4X4_50', marker)]
        assert _edge(found[('DICT_4X4_50', marker)]) == pytest.approx(0.1, abs=RASTER)
        assert parse_targets(text.splitlines()[0].strip()) == (
            MarkerSpec('DICT_4X4_50', None, 0.1),
        )
        assert f'id {marker}' in text


def test_a_charuco_board_prints_at_its_size(tmp_path: Path) -> None:
    spec = TargetSpec(5, 4, 0.035, 0.026, 'DICT_4X4_50')
    path = _write(tmp_path, spec.text())
    ((_, grey, text),) = _pages(path)
    board, *markers = _images(path)
    assert board[2:] - board[:2] == pytest.approx([0.175, 0.14], abs=1e-6)
    assert len(markers) == spec.squares_x * spec.squares_y // 2
    for left, bottom, right, top in markers:
        assert (right - left, top - bottom) == pytest.approx((0.026, 0.026), abs=1e-6)
    ids, px = detect_charuco(grey, spec)
    # Every inner corner, each where the board has it: the layout is OpenCV's.
    assert sorted(ids) == list(range((spec.squares_x - 1) * (spec.squares_y - 1)))
    layout = spec.corners()[ids, :2]
    offset = px / PX_PER_M - layout
    assert np.ptp(offset, axis=0) == pytest.approx([0, 0], abs=RASTER)
    assert parse_targets(text.splitlines()[0].strip()) == (spec,)


def test_a_scale_bar_prints_its_two_markers_the_length_apart(tmp_path: Path) -> None:
    path = _write(tmp_path, 'bar:DICT_4X4_50:3:4:0.2', bar_marker=0.05)
    ((_, grey, text),) = _pages(path)
    first, second = _images(path)
    assert second[0] - first[0] == pytest.approx(0.2, abs=1e-6)
    assert first[2] - first[0] == pytest.approx(0.05, abs=1e-6)
    found = detect_markers(grey, ['DICT_4X4_50'])
    assert sorted(found) == [('DICT_4X4_50', 3), ('DICT_4X4_50', 4)]
    centres = [found[('DICT_4X4_50', m)].mean(axis=0) for m in (3, 4)]
    distance = float(np.linalg.norm(centres[1] - centres[0])) / PX_PER_M
    assert distance == pytest.approx(0.2, abs=RASTER)
    assert _edge(found[('DICT_4X4_50', 3)]) == pytest.approx(0.05, abs=RASTER)
    assert parse_targets(text.splitlines()[0].strip()) == (BarSpec('DICT_4X4_50', 3, 4, 0.2),)


def test_several_targets_one_page_each(tmp_path: Path) -> None:
    spec = 'aruco:DICT_4X4_50:1:0.1,charuco:3x3:0.04:0.03'
    texts = [text.splitlines()[0].strip() for _, _, text in _pages(_write(tmp_path, spec))]
    assert [parse_targets(t)[0] for t in texts] == list(parse_targets(spec))


@pytest.mark.parametrize(
    ('spec', 'paper', 'reason'),
    [
        ('charuco:5x4:0.08:0.06:DICT_4X4_50', 'a4', 'smallest paper that takes it is A2'),
        ('aruco:DICT_4X4_50:0:0.2', 'a4', 'smallest paper that takes it is TABLOID'),
        ('bar:DICT_4X4_50:0:1:1.5', 'a4', 'no paper here'),
        ('bar:DICT_4X4_50:0:1:0.2', 'a4', 'leave 20.0 mm between them'),
    ],
)
def test_a_target_that_does_not_fit_is_refused_with_the_reason(
    spec: str, paper: str, reason: str
) -> None:
    marker = {'bar_marker': 0.18} if spec.endswith(':0.2') and spec.startswith('bar') else {}
    with pytest.raises(StockpileError, match=reason):
        layout_pages(spec, paper, **marker)  # type: ignore[arg-type]


def test_a_set_id_past_the_dictionary_or_an_unknown_paper_is_refused() -> None:
    with pytest.raises(StockpileError, match='ids 0 to 49'):
        layout_pages('aruco:DICT_4X4_50:*:0.1', ids=(3, 50))
    with pytest.raises(StockpileError, match='a4, '):
        layout_pages('aruco:DICT_4X4_50:1:0.1', 'b5')
    with pytest.raises(StockpileError, match='no target'):
        layout_pages(' , ')


def test_the_command_writes_the_pdf_or_refuses(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / 'm.pdf'
    assert main(['target', '--out', str(out), 'aruco:DICT_4X4_50:0:0.15']) == 0
    assert out.exists() and 'print at 100 %' in capsys.readouterr().out
    assert main(['target', '--out', str(tmp_path / 'b.pdf'), 'charuco:5x4:0.08:0.06']) == 2
    assert 'does not fit A4' in capsys.readouterr().err and not (tmp_path / 'b.pdf').exists()
    assert main(['target', '--out', str(tmp_path / 'b.pdf'), '--paper', 'a2',
                 'charuco:5x4:0.08:0.06']) == 0  # fmt: skip
    assert main(['target', '--out', str(tmp_path / 's.pdf'), '--ids', '2,5',
                 'aruco:DICT_4X4_50:*:0.1']) == 0  # fmt: skip
    assert len(pdfium.PdfDocument(str(tmp_path / 's.pdf'))) == 2
