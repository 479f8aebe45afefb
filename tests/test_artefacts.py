"""The stage artefacts: one JSON round trip each, schemas checked, bad fields refused."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest

from stockpile_ros.artefacts import (
    ArtefactError,
    DenseSummary,
    KeyframePose,
    KeyframeRecord,
    KeyframeSummary,
    MeshInfo,
    ModelImages,
    OdometryEntry,
    ScaleRecord,
    SimilarityRecord,
    SparseSummary,
    from_json,
    load,
    save,
    to_json,
)
from stockpile_ros.camera import CameraModel


def _mesh_info() -> MeshInfo:
    scale = ScaleRecord('target', 0.5, 0.002, {'fit': 0.001}, 'ChArUco')
    poses = [KeyframePose(7, [1.0, 2.0, 3.0], [0.0, 0.0, 0.0, 1.0], 'kf_00000_000000.png')]
    return MeshInfo(scale=scale, units='m', keyframes=poses, poisson={'depth': 9})


def test_each_record_survives_its_round_trip(tmp_path: Path) -> None:
    camera = CameraModel.from_fov(64, 48, 60.0)
    odometry = OdometryEntry([1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0], camera_position=[1, 0, 1.5])
    record = KeyframeRecord('kf.png', 5, 2, camera, odometry, 'parallax', 3.5, {'later': 1})
    back = KeyframeRecord.from_line(record.to_line())
    assert back.odometry == odometry and back.extra == {'later': 1}
    assert back.camera is not None and np.array_equal(back.camera.k, camera.k)
    sparse = SparseSummary(3, 4, 0.75, 1, 100, 0.4, 900.0, 'prior', [], 'sequential', '',
                           'incremental', ['c.png'], [ModelImages(3, ['a', 'b', 'd'])])  # fmt: skip
    dense = DenseSummary('sgbm-pairs', False, 1000, voxel=math.nan)
    for item, cls in ((sparse, SparseSummary), (dense, DenseSummary), (_mesh_info(), MeshInfo)):
        path = tmp_path / f'{cls.__name__}.json'
        save(item, path)
        again = load(cls, path)
        assert to_json(again) == to_json(item)
    # JSON has no NaN: an undefined number is null on disk and NaN again when read.
    assert json.loads((tmp_path / 'DenseSummary.json').read_text())['voxel'] is None
    assert math.isnan(load(DenseSummary, tmp_path / 'DenseSummary.json').voxel)


def test_a_newer_or_another_schema_is_refused(tmp_path: Path) -> None:
    path = tmp_path / 'mesh.json'
    data = to_json(_mesh_info())
    path.write_text(json.dumps({**data, 'schema': 'stockpile-mesh/2'}))
    with pytest.raises(ArtefactError, match='newer'):
        load(MeshInfo, path)
    path.write_text(json.dumps({**data, 'schema': 'stockpile-report/2'}))
    with pytest.raises(ArtefactError, match='expected'):
        load(MeshInfo, path)


@pytest.mark.parametrize(
    ('change', 'why'),
    [
        ({'units': 'feet'}, 'not one of'),
        ({'keyframes': [{'stamp_ns': 'soon', 'position': [], 'orientation_xyzw': []}]}, 'int'),
        ({'keyframes': [{'position': [0, 0, 0]}]}, 'stamp_ns'),
        ({'scale': {'method': 'none'}}, 'units'),  # metres without a scale
        ({'ground_inliers': True}, 'int'),
    ],
)
def test_a_bad_field_is_refused_with_where_it_is(change: dict[str, object], why: str) -> None:
    data = {**to_json(_mesh_info()), **change}
    with pytest.raises(ArtefactError, match=why):
        from_json(MeshInfo, data)


def test_docs_name_every_field() -> None:
    doc = (Path(__file__).resolve().parent.parent / 'docs' / 'formats.md').read_text()
    records = (KeyframeRecord, OdometryEntry, KeyframeSummary, SparseSummary, ModelImages,
               DenseSummary, MeshInfo, ScaleRecord, SimilarityRecord, KeyframePose)  # fmt: skip
    for record in records:
        missing = [f.name for f in dataclasses.fields(record) if f.name != 'extra']
        missing = [name for name in missing if f'`{name}`' not in doc and f'"{name}"' not in doc]
        assert not missing, f'{record.__name__}: docs/formats.md does not name {missing}'
