"""`stockpile replay` over hand-made and simulated bags: outputs, diagnostics, failures."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosbags.highlevel import AnyReader

from stockpile_ros.bagio.writer import BagWriter
from stockpile_ros.camera import CameraModel
from stockpile_ros.cli import main
from stockpile_ros.replay import replay
from stockpile_ros.ros import messages as m
from stockpile_ros.ros import topics
from stockpile_ros.settings import build_settings

CAMERA = CameraModel(64, 48, np.array([[60.0, 0, 32], [0, 60.0, 24], [0, 0, 1]]), np.zeros(5),
                     'plumb_bob', 'camera_optical')  # fmt: skip
SECOND = 1_000_000_000
CONFIG = Path(__file__).resolve().parent.parent / 'config' / 'stockpile.yaml'


def _image(i: int) -> np.ndarray:
    rng = np.random.default_rng(i)
    return (rng.random((48, 64, 3)) * 255).astype(np.uint8)


def _bag(path: Path, frames: int, *, info: bool = True, encoding: str = 'rgb8',
         triggers: tuple[int, ...] = ()) -> Path:  # fmt: skip
    with BagWriter(path) as bag:
        f = bag.factory
        for i in range(frames):
            stamp = SECOND + i * SECOND // 10
            msg = m.image(f, _image(i), stamp, 'camera_optical')
            msg.encoding = encoding
            bag.write('/camera/image_raw', msg, stamp)
            if info:
                bag.write('/camera/camera_info', m.camera_info(f, CAMERA, stamp), stamp)
            if i in triggers:
                bag.write('/' + topics.TRIGGER, f.cls('std_msgs/msg/Empty')(), stamp + 1)
    return path


def _read(bag: Path) -> dict[str, list[Any]]:
    """Every message by topic, with a plain AnyReader that was not handed our .msg files."""
    out: dict[str, list[Any]] = {}
    with AnyReader([bag]) as reader:
        for conn, _, raw in reader.messages():
            out.setdefault(conn.topic, []).append(reader.deserialize(raw, conn.msgtype))
    return out


def _diagnostics(msgs: dict[str, list[Any]]) -> list[tuple[str, int, str]]:
    return [(s.name, s.level, s.message) for a in msgs['/diagnostics'] for s in a.status]


def test_too_few_keyframes_at_a_recorded_trigger(tmp_path: Path) -> None:
    bag = _bag(tmp_path / 'in', 3, triggers=(1,))
    summary = replay(bag, tmp_path / 'out', build_settings())
    assert not summary.ok and summary.triggers == 1  # the recorded trigger, not the end
    assert summary.camera_info
    # One MCAP file, not a rosbag2 folder.
    assert summary.output_bag == tmp_path / 'out' / 'replay.mcap' and summary.output_bag.is_file()
    msgs = _read(summary.output_bag)
    assert len(msgs['/camera/image_raw']) == 3 and len(msgs['/camera/camera_info']) == 3
    # One status per frame, and one more when the end of the bag sends the last keyframe (the bag
    # has no odometry, so it waited for frames past the interpolation gap that never came).
    assert len(msgs['/' + topics.KEYFRAME_STATUS]) == 4
    kept = msgs['/' + topics.KEYFRAMES]
    assert [k.index for k in kept] == list(range(len(kept))) and not kept[-1].has_odometry
    name, level, text = _diagnostics(msgs)[-1]
    assert (name, level) == ('stockpile/keyframes', 2) and 'keyframe' in text
    final = msgs['/' + topics.STATUS][-1]
    assert final.state == 5 and final.advice  # FAILED, with advice
    assert any('at least 3 needed' in p for p in summary.problems)


def test_no_camera_info_is_reported_and_the_cli_exits_1(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = _bag(tmp_path / 'in', 2, info=False)
    assert main(['replay', str(bag), '--out', str(tmp_path / 'out')]) == 1
    err = capsys.readouterr().err
    assert 'self-calibrated' in err and 'Traceback' not in err
    diags = _diagnostics(_read(tmp_path / 'out' / 'replay.mcap'))
    assert ('stockpile/camera_info', 1) in [(n, lvl) for n, lvl, _ in diags]


def test_unknown_encoding_frames_are_skipped_and_counted(tmp_path: Path) -> None:
    bag = _bag(tmp_path / 'in', 4, encoding='weird16')
    summary = replay(bag, tmp_path / 'out', build_settings())
    assert (summary.frames, summary.skipped, summary.ok) == (0, 4, False)
    diags = _diagnostics(_read(summary.output_bag))
    camera = [t for n, lvl, t in diags if n == 'stockpile/camera' and lvl == 2]
    assert any('weird16' in t for t in camera) and any('4 frames skipped' in t for t in camera)


def test_refuses_to_overwrite_and_bad_parameters_are_user_errors(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = _bag(tmp_path / 'in', 2)
    out = tmp_path / 'out'
    assert main(['replay', str(bag), '--out', str(out), '--set', 'sfm.overlap=0']) == 2
    assert 'outside' in capsys.readouterr().err
    replay(bag, out, build_settings())
    assert main(['replay', str(bag), '--out', str(out)]) == 2
    assert 'holds a run of this input' in capsys.readouterr().err


def test_a_folder_belongs_to_one_input_and_a_rerun_is_asked_for(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    one, other = _bag(tmp_path / 'one', 6), _bag(tmp_path / 'other', 7)
    out = tmp_path / 'out'
    first = replay(one, out, build_settings())
    kept = len((out / 'work' / 'keyframes' / 'keyframes.jsonl').read_text().splitlines())
    assert json.loads((out / 'run.json').read_text())['state'] == 'failed'  # too few to reconstruct
    # Another bag is refused, never appended; so are other parameters.
    assert main(['replay', str(other), '--out', str(out), '--resume']) == 2
    assert 'another input' in capsys.readouterr().err
    assert main(['replay', str(one), '--out', str(out), '--resume',
                 '--set', 'sfm.max_features=999']) == 2  # fmt: skip
    assert 'other parameters' in capsys.readouterr().err
    # The same bag resumed keeps each keyframe once (a rerun after kill -9 doubled them).
    again = replay(one, out, build_settings(), resume=True)
    assert again.keyframes == first.keyframes
    assert len((out / 'work' / 'keyframes' / 'keyframes.jsonl').read_text().splitlines()) == kept
    # --fresh starts over on the other bag; the earlier result and bag are gone.
    assert main(['replay', str(other), '--out', str(out), '--fresh']) == 1
    assert json.loads((out / 'run.json').read_text())['input'] == str(other)
    assert not (out / 'result').exists()


def test_file_system_faults_are_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = _bag(tmp_path / 'in', 2)
    (tmp_path / 'file').write_text('x')
    assert main(['replay', str(bag), '--out', str(tmp_path / 'file')]) == 2
    assert 'is a file' in capsys.readouterr().err
    # A folder that cannot be made (here under a file; a read-only mount fails the same way).
    assert main(['replay', str(bag), '--out', str(tmp_path / 'file' / 'out')]) == 2
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and str(tmp_path / 'file') in err and 'Traceback' not in err
