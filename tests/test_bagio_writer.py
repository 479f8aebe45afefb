from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from mcap.reader import make_reader
from rosbags.highlevel import AnyReader
from rosbags.interfaces import ConnectionExtRosbag2, QosDurability, QosReliability

from stockpile_ros.bagio.reader import BagReader
from stockpile_ros.bagio.writer import BagWriter
from stockpile_ros.cli import main
from stockpile_ros.ros import messages as m
from stockpile_ros.ros import outputs as o

S = 1_000_000_000
STATUS = '/stockpile/status'
IMAGE = '/camera/image_raw'


def _write(path: Path, **kwargs: Any) -> Path:
    """Two PipelineStatus on a latched topic and three images on a volatile one."""
    with BagWriter(path, latched={STATUS}, **kwargs) as bag:
        f = bag.factory
        for i in range(3):
            img = np.full((6, 8, 3), 40 * i, np.uint8)
            bag.write(IMAGE, m.image(f, img, S + i, 'cam'), S + i)
        for i, state in enumerate(('segmenting', 'done')):
            msg = o.pipeline_status(f, 2 * S + i, state, 'segment', 0.5 * (i + 1), 7, 0.8, 'ok')
            bag.write(STATUS, msg, 2 * S + i)
    return path


def _summary(path: Path) -> Any:
    with path.open('rb') as stream:
        summary = make_reader(stream).get_summary()
    assert summary is not None
    return summary


def _qos_by_topic(path: Path) -> dict[str, list[dict[str, Any]]]:
    """Each channel's offered QoS, parsed from the YAML string in its MCAP metadata."""
    summary = _summary(path)
    return {
        c.topic: yaml.safe_load(c.metadata['offered_qos_profiles'])
        for c in summary.channels.values()
    }


def test_one_mcap_file_and_nothing_else(tmp_path: Path) -> None:
    path = _write(tmp_path / 'out' / 'replay.mcap')
    assert path.is_file()
    assert [p.name for p in (tmp_path / 'out').iterdir()] == ['replay.mcap']
    with path.open('rb') as stream:
        assert stream.read(8) == b'\x89MCAP0\r\n'


def test_round_trip_through_both_readers(tmp_path: Path) -> None:
    path = _write(tmp_path / 'bag.mcap')
    with BagReader(path) as bag:
        got = list(bag.messages([IMAGE, STATUS]))
    assert [(t, i, ns) for t, i, ns, _ in got] == [
        (IMAGE, 0, S),
        (IMAGE, 1, S + 1),
        (IMAGE, 2, S + 2),
        (STATUS, 0, 2 * S),
        (STATUS, 1, 2 * S + 1),
    ]
    last = got[-1][3]
    assert (last.state, last.stage, last.keyframes, last.message) == (4, 'segment', 7, 'ok')
    assert last.progress == pytest.approx(1.0) and last.header.stamp.nanosec == 1
    assert bytes(got[2][3].data) == bytes([80]) * (6 * 8 * 3) and got[2][3].encoding == 'rgb8'
    # A plain rosbags reader, not handed our .msg files, decodes from the embedded definitions.
    with AnyReader([path]) as reader:
        decoded = {
            conn.topic: reader.deserialize(raw, conn.msgtype) for conn, _, raw in reader.messages()
        }
        durability = {
            c.topic: c.ext.offered_qos_profiles[0].durability
            for c in reader.connections
            if isinstance(c.ext, ConnectionExtRosbag2)
        }
    assert decoded[STATUS].state == 4 and decoded[STATUS].advice == ''
    assert decoded[IMAGE].width == 8
    assert durability == {STATUS: QosDurability.TRANSIENT_LOCAL, IMAGE: QosDurability.VOLATILE}


def test_embedded_definitions_are_full_ros2msg_text(tmp_path: Path) -> None:
    schemas = {s.name: s for s in _summary(_write(tmp_path / 'bag.mcap')).schemas.values()}
    status = schemas['stockpile_msgs/msg/PipelineStatus']
    assert status.encoding == 'ros2msg'
    text = status.data.decode()
    # The top-level definition, then each nested type's after a line of 80 '=' and its name, as
    # rosbag2 concatenates them (rosbags regenerates the text: no comments).
    top, header, time = text.split('=' * 80 + '\n')
    assert top.startswith('uint8 STATE_IDLE=0\n') and 'std_msgs/Header header\n' in top
    assert header.startswith('MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\n')
    assert time.startswith('MSG: builtin_interfaces/Time\nint32 sec\n')


def test_latched_topic_offered_transient_local_others_volatile(tmp_path: Path) -> None:
    qos = _qos_by_topic(_write(tmp_path / 'bag.mcap'))
    assert len(qos[STATUS]) == 1 and len(qos[IMAGE]) == 1
    latched, other = qos[STATUS][0], qos[IMAGE][0]
    assert (latched['durability'], latched['reliability']) == ('transient_local', 'reliable')
    assert (latched['history'], latched['depth']) == ('keep_last', 1)
    assert (other['durability'], other['reliability']) == ('volatile', 'reliable')


def test_chunks_are_zstd_compressed(tmp_path: Path) -> None:
    summary = _summary(_write(tmp_path / 'bag.mcap'))
    chunks = summary.chunk_indexes
    assert chunks and {c.compression for c in chunks} == {'zstd'}
    assert summary.statistics.message_count == 5
    assert sum(c.compressed_size for c in chunks) < sum(c.uncompressed_size for c in chunks)


def test_embedded_rosbag2_metadata_names_the_final_file(tmp_path: Path) -> None:
    path = _write(tmp_path / 'replay.mcap')
    with path.open('rb') as stream:
        records = [r for r in make_reader(stream).iter_metadata() if r.name == 'rosbag2']
    assert len(records) == 1
    info = yaml.safe_load(records[0].metadata['serialized_metadata'])
    assert info['relative_file_paths'] == ['replay.mcap'] and info['version'] == 9
    # rosbag2 reads custom_data as a string map; null would not be one.
    assert isinstance(info['custom_data'], dict)
    qos = {t['topic_metadata']['name']: t['topic_metadata']['offered_qos_profiles']
           for t in info['topics_with_message_count']}  # fmt: skip
    assert qos[STATUS][0]['durability'] == 'transient_local'


def test_existing_path_is_refused(tmp_path: Path) -> None:
    path = tmp_path / 'bag.mcap'
    path.write_bytes(b'keep me')
    with pytest.raises(FileExistsError):
        BagWriter(path)
    folder = tmp_path / 'folder'
    folder.mkdir()
    with pytest.raises(FileExistsError):
        BagWriter(folder)
    assert path.read_bytes() == b'keep me' and list(folder.iterdir()) == []


def test_a_path_that_appears_while_writing_is_not_overwritten(tmp_path: Path) -> None:
    path = tmp_path / 'bag.mcap'
    with pytest.raises(FileExistsError, match='appeared while writing'), BagWriter(path) as bag:
        bag.write('/chatter', bag.factory.cls('std_msgs/msg/String')(data='x'), S)
        path.write_bytes(b'someone else')
    assert path.read_bytes() == b'someone else'
    assert [p.name for p in tmp_path.iterdir()] == ['bag.mcap']


@pytest.mark.parametrize('error', [RuntimeError, KeyboardInterrupt])
def test_an_interrupted_write_leaves_no_final_file(
    tmp_path: Path, error: type[BaseException]
) -> None:
    path = tmp_path / 'replay.mcap'
    with pytest.raises(error), BagWriter(path, latched={STATUS}) as bag:
        f = bag.factory
        bag.write(STATUS, o.pipeline_status(f, S, 'idle', '', 0.0, 0, 0.0, 'start'), S)
        raise error('stopped')
    assert not path.exists()
    partial = tmp_path / 'replay.mcap.partial'
    assert bag.partial_path == partial
    assert [p.name for p in tmp_path.iterdir()] == [partial.name]
    # What was written before the interruption is a finalised MCAP (summary and all).
    summary = _summary(partial)
    assert summary.statistics.message_count == 1


def test_a_second_interrupted_run_replaces_the_partial_bag(tmp_path: Path) -> None:
    path = tmp_path / 'replay.mcap'
    for count in (2, 1):
        with pytest.raises(RuntimeError), BagWriter(path) as bag:
            for i in range(count):
                bag.write('/chatter', bag.factory.cls('std_msgs/msg/String')(data='x'), S + i)
            raise RuntimeError
    assert _summary(tmp_path / 'replay.mcap.partial').statistics.message_count == 1


def test_other_names_give_a_rosbag2_folder_with_the_same_qos(tmp_path: Path) -> None:
    path = _write(tmp_path / 'pile')
    assert sorted(p.name for p in path.iterdir()) == ['metadata.yaml', 'pile.mcap']
    assert [p.name for p in tmp_path.iterdir()] == ['pile']
    info = yaml.safe_load((path / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    qos = {t['topic_metadata']['name']: t['topic_metadata']['offered_qos_profiles'][0]
           for t in info['topics_with_message_count']}  # fmt: skip
    assert qos[STATUS]['durability'] == 'transient_local' and qos[IMAGE]['durability'] == 'volatile'
    assert _qos_by_topic(path / 'pile.mcap')[STATUS][0]['durability'] == 'transient_local'
    with BagReader(path) as bag:
        assert bag.topics_of(['stockpile_msgs/msg/PipelineStatus']) == [(STATUS, 2)]


def test_latched_names_must_be_absolute(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match='stockpile/status'):
        BagWriter(tmp_path / 'bag.mcap', latched={'stockpile/status'})


def test_write_needs_an_open_writer(tmp_path: Path) -> None:
    bag = BagWriter(tmp_path / 'bag.mcap')
    with pytest.raises(RuntimeError, match='not open'):
        bag.write('/chatter', bag.factory.cls('std_msgs/msg/String')(data='x'), S)
    assert not (tmp_path / 'bag.mcap').exists()


def test_stockpile_info_reads_the_single_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = _write(tmp_path / 'replay.mcap')
    assert main(['info', str(path)]) == 0
    out = capsys.readouterr().out
    assert STATUS in out and IMAGE in out


def test_reliability_is_reliable_for_every_topic(tmp_path: Path) -> None:
    with AnyReader([_write(tmp_path / 'bag.mcap')]) as reader:
        profiles = [
            q for c in reader.connections if isinstance(c.ext, ConnectionExtRosbag2)
            for q in c.ext.offered_qos_profiles
        ]  # fmt: skip
    assert len(profiles) == 2
    assert {q.reliability for q in profiles} == {QosReliability.RELIABLE}
