"""Plain-text rendering of an evaluation dict for a terminal."""

from __future__ import annotations

from typing import Any

from .metrics import QUANTITIES

__all__ = ['format_table']


def _num(value: float | None, fmt: str, suffix: str = '') -> str:
    return '-' if value is None else f'{value:{fmt}}{suffix}'


def _pct(value: float | None) -> str:
    # Rounding first, then adding 0.0, prints a tiny negative error as +0.00 rather than -0.00.
    return _num(None if value is None else round(100.0 * value, 2) + 0.0, '+.2f', ' %')


def _times100(value: float | None) -> float | None:
    return None if value is None else 100.0 * value


def _plus(ids: list[int]) -> str:
    return '+'.join(str(i) for i in ids)


def _ids(items: list[Any]) -> str:
    return ', '.join(str(i) for i in items) if items else 'none'


def _alignment_lines(al: dict[str, Any]) -> list[str]:
    lines = [
        f'Alignment: {al["method"]} on {al["matched_keyframes"]}/{al["keyframes"]} keyframes; '
        f'scale {al["scale"]:.4f} true m per result unit, rotation {al["rotation_deg"]:.2f} deg',
        f'  camera centres: RMSE {_num(al["centre_rmse_m"], ".4f", " m")} '
        f'({_num(_times100(al["centre_rmse_rel_extent"]), ".2f", " %")} of the pile extent '
        f'{al["pile_extent_m"]:.3f} m), median {_num(al["centre_median_m"], ".4f", " m")}; '
        f'orientation median {_num(al["orientation_median_deg"], ".2f", " deg")}',
    ]
    if al['note']:
        lines.append(f'  note: {al["note"]}')
    return lines


def _interest_line(it: dict[str, Any]) -> str:
    return (
        f'  rocks of interest (visible, b >= {it["min_b_m"]:.4g} m from the {it["source"]}; '
        f'{it["true_rocks_under"]} true rocks under it left aside): {it["true_rocks"]} true, '
        f'{it["detected"]} detected, precision {_num(it["precision"], ".3f")}, '
        f'recall {_num(it["recall"], ".3f")}; clusters of smaller rocks: {_ids(it["clusters"])}'
    )


def _detection_lines(det: dict[str, Any]) -> list[str]:
    false = [f'{f["id"]} (on {f["lies_on"]})' for f in det['false']]
    merges = [
        f'{m["result_id"]} <- true {"+".join(map(str, m["true_ids"]))}' for m in det['merges']
    ]
    splits = [
        f'true {s["true_id"]} -> {"+".join(map(str, s["result_ids"]))}' for s in det['splits']
    ]
    return [
        f'Detection: {det["result_rocks"]} result rocks, {det["true_rocks"]} true rocks '
        f'({det["true_rocks_visible"]} with visible fraction >= {det["visible_threshold"]:g}); '
        f'{det["detected"]} detected',
        f'  precision {_num(det["precision"], ".3f")}, recall {_num(det["recall"], ".3f")}; '
        f'visible rocks: precision {_num(det["precision_visible"], ".3f")}, '
        f'recall {_num(det["recall_visible"], ".3f")}',
        _interest_line(det['of_interest']),
        f'  missed (visible): {_ids(det["missed"])}; '
        f'not found (hidden): {_ids(det["missed_hidden"])}',
        f'  false: {_ids(false)}',
        f'  merges: {_ids(merges)}; splits: {_ids(splits)}',
        f'  distance gate {det["max_distance_m"]:.4f} m; result surface off every true surface: '
        f'{_num(_times100(det["off_surface_area_share"]), ".2f", " %")}',
    ]


def _size_lines(sizes: dict[str, Any], rescaled: bool) -> list[str]:
    how = 'multiplied by the alignment scale' if rescaled else 'as reported'
    header = f'{"true":>5} {"res":>5} {"IoU":>5} {"vis":>5}'
    for q in QUANTITIES:
        unit = 'm3' if q == 'volume' else 'm'
        header += f' {f"{q} [{unit}]":>11} {"error":>8}'
    lines = [f'Sizes (true values in truth metres; result sizes {how}):', header]
    for rock in sizes['rocks']:
        row = (
            f'{rock["true_id"]:>5} {rock["result_id"]:>5} {rock["iou"]:>5.2f} '
            f'{_num(rock["visible_fraction"], ">5.2f")}'
        )
        for q in QUANTITIES:
            row += f' {_num(rock["true"][q], ">11.4g")} {_pct(rock["relative_error"][q]):>8}'
        lines.append(row)
    rows = (
        ('summary', 'median_abs_pct', 'median |err|'),
        ('summary', 'mean_abs_pct', 'mean |err|'),
        ('summary_visible', 'median_abs_pct', 'visible: median |err|'),
    )
    for group, key, label in rows:
        row = f'{label:>23}'
        for q in QUANTITIES:
            row += f' {"":>11} {_num(sizes[group][q][key], ".2f", " %"):>8}'
        lines.append(row)
    lines.append(f'  volume MAPE {_num(sizes["volume_mape_pct"], ".2f", " %")}')
    return lines


def format_table(evaluation: dict[str, Any]) -> str:
    """Render the output of :func:`stockpile_ros.tools.evaluation.evaluate` as readable text."""
    sc = evaluation['scale']
    gr = evaluation['gradation']
    judged = _pct(sc['error']) if sc['error'] is not None else f'not judged ({sc["note"]})'
    lines = [f'Result {evaluation["result"]} against truth {evaluation["truth"]}']
    lines += _alignment_lines(evaluation['alignment'])
    lines.append(
        f'Scale: method "{sc["method"]}", result length / true length '
        f'{sc["result_per_true_length"]:.4f}, scale error {judged}'
    )
    lines += _detection_lines(evaluation['detection'])
    lines += _size_lines(evaluation['sizes'], sc['sizes_rescaled'])
    lines.append(
        f'D50 by mass: true {_num(gr["d50_true_m"], ".4f", " m")}, '
        f'result {_num(gr["d50_result_m"], ".4f", " m")}, error {_pct(gr["d50_error"])}'
    )
    return '\n'.join(lines)
