from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from stockpile_ros.artefacts import WorkFolder
from stockpile_ros.bagdrive import keyframes_from_bag
from stockpile_ros.recon.keyframes import KeyframeStore
from stockpile_ros.settings import build_settings
from stockpile_ros.tools.sim.camera_path import PathConfig
from stockpile_ros.tools.sim.pile import PileConfig, parse_gradation
from stockpile_ros.tools.sim.record import SimulationConfig, simulate, truth_folder
from stockpile_ros.tools.sim.scene import SceneConfig

TINY = SimulationConfig(
    seed=5,
    scene=SceneConfig(
        pile=PileConfig(rocks=3, gradation=parse_gradation('0.12:0.18'), subdivisions=3),
        ground_px=256,
    ),
    # Two heights: the camera rides a mast whose height is on /tf, not /tf_static.
    path=PathConfig(kind='arc', heights=(1.0, 1.5)),
    width=96,
    height=72,
    fps=4.0,
    frames=8,
    odom_rate=20.0,
    threads=1,
)


def test_bag_keyframes_carry_camera_and_odometry_and_resume(tmp_path: Path) -> None:
    bag = tmp_path / 'bag'
    simulate(TINY, bag)
    truth = json.loads((truth_folder(bag) / 'truth.json').read_text())
    true_centres = {c['stamp_ns']: np.asarray(c['position']) for c in truth['cameras']}
    work = WorkFolder(tmp_path / 'work')
    every = {'selector.min_parallax': 0.0, 'selector.min_spacing': 1, 'selector.blur_ratio': 0.0,
             'work_dir': str(work.root)}  # fmt: skip
    first = keyframes_from_bag(bag, build_settings({**every, 'selector.max_keyframes': 3}))
    assert first.keyframes == 3
    # A later run (the "restart") continues after the frames already kept.
    rest = keyframes_from_bag(bag, build_settings({**every, 'selector.max_keyframes': 8}))
    assert rest.new == 5 and rest.keyframes == 8
    records = KeyframeStore(work.keyframes).records
    assert [r.index for r in records] == list(range(8))
    for record in records:
        assert record.camera is not None and record.camera.width == 96
        assert record.odometry is not None and record.odometry.frame_id == 'odom'
        # The optical centre from odometry and /tf_static is the true camera position.
        np.testing.assert_allclose(
            record.odometry.camera_position, true_centres[record.stamp_ns], atol=1e-3
        )
