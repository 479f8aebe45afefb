from __future__ import annotations

import json
import re
from pathlib import Path

import yaml

from stockpile_ros.ros import topics

DASHBOARDS = Path(__file__).resolve().parents[1] / 'dashboards'
KNOWN = {'/' + t.name.lstrip('/') for t in topics.TABLE}


def _topic(path: str) -> str:
    """The topic of a Foxglove message path (``/a/b.field[:]{filter}`` -> ``/a/b``)."""
    return re.split(r'[.{\[]', path, maxsplit=1)[0]


def test_rviz_uses_the_topics_of_the_bags_and_nodes() -> None:
    config = yaml.safe_load((DASHBOARDS / 'stockpile.rviz').read_text())
    displays = config['Visualization Manager']['Displays']
    used = {d['Topic']['Value'] for d in displays if 'Topic' in d}
    assert used and used <= KNOWN, used - KNOWN
    camera = next(d for d in displays if d['Class'] == 'rviz_default_plugins/Image')
    # The bags carry JPEG frames only: the display subscribes through the compressed transport.
    assert camera['Topic']['Value'] == '/camera/image_raw/compressed'


def test_foxglove_plots_passing_against_size_and_shows_the_verdict() -> None:
    config = json.loads((DASHBOARDS / 'foxglove_layout.json').read_text())['configById']
    paths = []
    for panel in config.values():
        paths += [panel.get('topicPath'), panel.get('path')]
        paths += [p['value'] for p in panel.get('paths', [])]
        paths += [panel.get('xAxisPath', {}).get('value')]
        paths += [panel.get('imageMode', {}).get(k) for k in ('imageTopic', 'calibrationTopic')]
        paths += list(panel.get('topics', {}))
    used = {_topic(p) for p in paths if p}
    assert used <= KNOWN, used - KNOWN
    plot = config['Plot!gradation']
    assert plot['xAxisVal'] == 'currentCustom'
    assert plot['xAxisPath']['value'] == '/stockpile/gradation.sizes[:]'
    assert {p['value'] for p in plot['paths']} >= {'/stockpile/gradation.percent_passing_mass[:]'}
    verdict = config['Indicator!verdict']
    assert verdict['path'] == '/stockpile/gradation.verdict'
    shown = {rule['rawValue'] for rule in verdict['rules']}
    assert shown == {'PASS', 'FAIL', 'UNDECIDED', 'REFUSED'}
    # Every field the layout reads is in the message.
    fields = (DASHBOARDS.parent / 'msg_schemas' / 'msg' / 'Gradation.msg').read_text()
    assert 'string verdict' in fields and 'string units' in fields
