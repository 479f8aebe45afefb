"""Read the two sides of an evaluation: the simulator's truth folder and a result folder.

Only the files of the contract in ``docs/formats.md`` are read: ``truth.json`` + ``scene.ply`` and
``report.json`` + ``segments.ply``. ``report.json`` is read as the
:class:`~stockpile_ros.result.Report` it was written as (its schema and every field checked);
``truth.json`` by the keys it needs.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.spatial.transform import Rotation

from ...artefacts import ArtefactError, load
from ...errors import StockpileError
from ...meshio import LabelledMesh, read_labelled_mesh
from ...result import Report, RockRecord

__all__ = [
    'EvaluationError',
    'Poses',
    'ResultSide',
    'Rock',
    'TruthSide',
    'load_result',
    'load_truth',
]

FloatArray = npt.NDArray[np.float64]


class EvaluationError(StockpileError):
    """A truth or result folder that cannot be evaluated, or a pair that cannot be compared."""


@dataclass
class Poses:
    """Stamped camera-to-world poses.

    Attributes:
        stamps_ns: N int64 stamps [ns].
        centres: Nx3 optical centres in the world frame.
        rotations: Nx3x3 rotations from the optical frame to the world frame.

    """

    stamps_ns: npt.NDArray[np.int64]
    centres: FloatArray
    rotations: FloatArray


@dataclass
class Rock:
    """The figures of one rock that the evaluation compares; None where the file gives none.

    Attributes:
        id: Rock id (> 0), as in the labelled mesh.
        centroid: Centroid in the file's frame, or None.
        a: Longest dimension.
        b: Intermediate dimension.
        c: Shortest dimension.
        volume: Volume.
        visible_fraction: Share of the surface seen (truth) or estimated as seen (result).

    """

    id: int
    centroid: FloatArray | None
    a: float | None
    b: float | None
    c: float | None
    volume: float | None
    visible_fraction: float | None


@dataclass
class TruthSide:
    """The simulator's truth (``truth.json`` + ``scene.ply``).

    Attributes:
        path: The truth folder.
        frame_id: Frame of every position in the truth.
        cameras: True pose of every recorded frame.
        rocks: True rocks by id.
        d50: True D50 by mass [m], or None.
        scene: Labelled scene mesh (ground 0, each rock's full mesh under its id).

    """

    path: Path
    frame_id: str
    cameras: Poses
    rocks: dict[int, Rock]
    d50: float | None
    scene: LabelledMesh


@dataclass
class ResultSide:
    """A segmentation result (``report.json`` + ``segments.ply``).

    Attributes:
        path: The result folder.
        frame_id: Frame of every position in the result.
        scale_method: ``scale.method`` of the report; ``"none"`` means arbitrary units.
        keyframes: Reported keyframe poses.
        rocks: Reported rocks by id.
        d50: Reported D50 by mass, or None.
        mesh: Segmented mesh (rock ids as in ``rocks``, 0 = ground or unassigned).
        min_rock_b: The smallest rock of interest the run segmented for
            (``segmentation.scale.min_rock_b``), in the result's units.

    """

    path: Path
    frame_id: str
    scale_method: str
    keyframes: Poses
    rocks: dict[int, Rock]
    d50: float | None
    mesh: LabelledMesh
    min_rock_b: float

    @property
    def metric(self) -> bool:
        """Whether the result claims metric units (any scale method but ``"none"``)."""
        return self.scale_method != 'none'


def _folder_and_file(path: str | Path, name: str, what: str) -> tuple[Path, Path]:
    p = Path(path)
    if p.is_dir():
        return p, p / name
    if not p.exists():
        raise EvaluationError(f'{p}: no such {what} folder (one holding {name}) or file')
    return p.parent, p


def _read_json(path: Path) -> dict[str, Any]:
    try:
        data = json.loads(path.read_text(encoding='utf-8'))
    except FileNotFoundError:
        raise EvaluationError(f'{path}: no such file') from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise EvaluationError(f'{path}: cannot read JSON ({exc})') from None
    if not isinstance(data, dict):
        raise EvaluationError(f'{path}: expected a JSON object')
    return data


def _read_mesh(path: Path) -> LabelledMesh:
    try:
        return read_labelled_mesh(path)
    except FileNotFoundError:
        raise EvaluationError(f'{path}: no such file') from None
    except (OSError, ValueError, KeyError, IndexError, UnicodeDecodeError) as exc:
        raise EvaluationError(f'{path}: cannot read the labelled mesh ({exc})') from None


def _number(value: Any) -> float | None:
    if value is None or isinstance(value, bool) or not isinstance(value, int | float):
        return None
    return float(value) if math.isfinite(value) else None


def _field(data: dict[str, Any], key: str, where: str) -> Any:
    if key not in data:
        raise EvaluationError(f'{where}: missing "{key}"')
    return data[key]


def _poses(items: Any, where: str) -> Poses:
    if not isinstance(items, list):
        raise EvaluationError(f'{where}: expected a list of poses')
    try:
        stamps = [int(p['stamp_ns']) for p in items]
        centres = [p['position'] for p in items]
        quats = [p['orientation_xyzw'] for p in items]
    except (KeyError, TypeError, ValueError) as exc:
        raise EvaluationError(f'{where}: malformed pose ({exc})') from None
    return _pose_arrays(stamps, centres, quats, where)


def _pose_arrays(stamps_ns: Any, centres: Any, quats_xyzw: Any, where: str) -> Poses:
    try:
        stamps = np.array(stamps_ns, dtype=np.int64)
        centres = np.array(centres, dtype=np.float64).reshape(-1, 3)
        quats = np.array(quats_xyzw, dtype=np.float64).reshape(-1, 4)
    except (TypeError, ValueError) as exc:
        raise EvaluationError(f'{where}: malformed pose ({exc})') from None
    if len(quats) and np.any(np.linalg.norm(quats, axis=1) < 1e-9):
        raise EvaluationError(f'{where}: zero quaternion')
    rots = Rotation.from_quat(quats).as_matrix() if len(quats) else np.zeros((0, 3, 3))
    return Poses(stamps_ns=stamps, centres=centres, rotations=rots.reshape(-1, 3, 3))


def _rocks(items: Any, where: str) -> dict[int, Rock]:
    if not isinstance(items, list):
        raise EvaluationError(f'{where}: "rocks" must be a list')
    rocks: dict[int, Rock] = {}
    for item in items:
        rid = item.get('id') if isinstance(item, dict) else None
        if not isinstance(rid, int) or isinstance(rid, bool) or rid <= 0:
            raise EvaluationError(f'{where}: rock with invalid id {rid!r} (ids are integers > 0)')
        if rid in rocks:
            raise EvaluationError(f'{where}: rock id {rid} listed twice')
        centroid = item.get('centroid')
        rocks[rid] = Rock(
            id=rid,
            centroid=None if centroid is None else np.asarray(centroid, dtype=np.float64),
            a=_number(item.get('a')),
            b=_number(item.get('b')),
            c=_number(item.get('c')),
            volume=_number(item.get('volume')),
            visible_fraction=_number(item.get('visible_fraction')),
        )
    return rocks


def _result_rocks(items: list[RockRecord], where: str) -> dict[int, Rock]:
    rocks: dict[int, Rock] = {}
    for item in items:
        if item.id <= 0:
            raise EvaluationError(f'{where}: rock with invalid id {item.id} (ids are integers > 0)')
        if item.id in rocks:
            raise EvaluationError(f'{where}: rock id {item.id} listed twice')
        rocks[item.id] = Rock(
            id=item.id,
            centroid=np.asarray(item.centroid, dtype=np.float64),
            a=_number(item.a),
            b=_number(item.b),
            c=_number(item.c),
            volume=_number(item.volume),
            visible_fraction=_number(item.visible_fraction),
        )
    return rocks


def _d50(data: dict[str, Any]) -> float | None:
    gradation = data.get('gradation')
    return _number(gradation.get('d50')) if isinstance(gradation, dict) else None


def load_truth(path: str | Path) -> TruthSide:
    """Read a truth folder (or its ``truth.json``; ``scene.ply`` is taken from beside it).

    Raises:
        EvaluationError: A file is missing or does not follow the truth contract.

    """
    folder, json_path = _folder_and_file(path, 'truth.json', 'truth')
    data = _read_json(json_path)
    where = str(json_path)
    if not str(data.get('schema', '')).startswith('stockpile-truth/'):
        raise EvaluationError(f'{where}: not a stockpile truth (schema {data.get("schema")!r})')
    return TruthSide(
        path=folder,
        frame_id=str(_field(data, 'frame_id', where)),
        cameras=_poses(_field(data, 'cameras', where), where + ' cameras'),
        rocks=_rocks(_field(data, 'rocks', where), where),
        d50=_d50(data),
        scene=_read_mesh(folder / 'scene.ply'),
    )


def load_result(path: str | Path) -> ResultSide:
    """Read a result folder (or its ``report.json``; ``segments.ply`` is taken from beside it).

    Raises:
        EvaluationError: A file is missing, or ``report.json`` is not a report this code reads
            (another or a newer schema, a missing field or one of the wrong type).

    """
    folder, json_path = _folder_and_file(path, 'report.json', 'result')
    if not json_path.is_file():
        raise EvaluationError(f'{json_path}: no such file')
    try:
        report = load(Report, json_path)
    except ArtefactError as exc:
        raise EvaluationError(str(exc)) from None
    where = str(json_path)
    keyframes = report.keyframes
    return ResultSide(
        path=folder,
        frame_id=report.frame_id,
        scale_method=report.scale.method,
        keyframes=_pose_arrays(
            [k.stamp_ns for k in keyframes],
            [k.position for k in keyframes],
            [k.orientation_xyzw for k in keyframes],
            where + ' keyframes',
        ),
        rocks=_result_rocks(report.rocks, where),
        d50=_number(report.gradation.d50),
        mesh=_read_mesh(folder / 'segments.ply'),
        min_rock_b=report.segmentation.scale.min_rock_b,
    )
