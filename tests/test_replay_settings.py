"""The parameter table, the ROS 2 params YAML loader and the option objects built from them."""

from __future__ import annotations

from pathlib import Path

import pytest

from stockpile_ros.errors import StockpileError
from stockpile_ros.recon.sfm import SfmOptions
from stockpile_ros.settings import (
    NODES,
    SETTINGS,
    build_settings,
    defaults,
    flatten,
    load_params_yaml,
    render_params_yaml,
    settings_for,
)

CONFIG = Path(__file__).resolve().parent.parent / 'config' / 'stockpile.yaml'


def test_every_number_has_a_range_holding_its_default_and_every_setting_a_description() -> None:
    for s in SETTINGS:
        assert s.description, s.name
        if isinstance(s.default, (int, float)) and not isinstance(s.default, bool):
            assert s.low is not None and s.high is not None, s.name
            assert s.low <= s.default <= s.high, s.name
    assert len({s.name for s in SETTINGS}) == len(SETTINGS)
    # The docstring parser keeps continuation lines.
    by_name = {s.name: s for s in SETTINGS}
    assert 'whatever the displacement' in by_name['selector.min_tracked'].description
    assert by_name['sfm.matcher'].choices == ()
    assert by_name['segment.seed_order'].choices == ('index', 'convex')


def test_each_component_declares_its_groups() -> None:
    names = {n: {s.name for s in settings_for(n)} for n in NODES}
    assert 'selector.min_parallax' in names['keyframes']
    assert 'sfm.max_features' in names['reconstruction']
    assert 'sfm.max_features' not in names['keyframes']
    assert 'measure.specific_gravity' in names['segmentation']
    assert all('work_dir' in v for v in names.values())
    with pytest.raises(StockpileError):
        settings_for('nope')


def test_flatten_and_yaml_sections(tmp_path: Path) -> None:
    assert flatten({'sfm': {'overlap': 8, 'x': {'y': 1}}, 'a': 2}) == {
        'sfm.overlap': 8,
        'sfm.x.y': 1,
        'a': 2,
    }
    path = tmp_path / 'p.yaml'
    path.write_text(
        '/**:\n  ros__parameters:\n    frame_id: pile\n    sfm:\n      overlap: 5\n'
        'other_node:\n  ros__parameters:\n    sfm:\n      overlap: 99\n'
        '/cart/stockpile_reconstruction:\n  ros__parameters:\n    sfm:\n      max_features: 2048\n'
    )
    values = load_params_yaml(path)
    assert values == {'frame_id': 'pile', 'sfm.overlap': 5, 'sfm.max_features': 2048}
    settings = build_settings(values)
    assert settings.recon.sfm == SfmOptions(overlap=5, max_features=2048)
    assert settings.frame_id == 'pile'


def test_yaml_errors_are_user_errors(tmp_path: Path) -> None:
    bad = tmp_path / 'bad.yaml'
    bad.write_text('/**:\n  frame_id: x\n')
    with pytest.raises(StockpileError, match='ros__parameters'):
        load_params_yaml(bad)
    with pytest.raises(StockpileError, match='cannot read'):
        load_params_yaml(tmp_path / 'missing.yaml')


def test_checks_names_types_ranges_and_choices() -> None:
    with pytest.raises(StockpileError, match=r'did you mean sfm\.max_features'):
        build_settings({'sfm.max_feature': 10})
    with pytest.raises(StockpileError, match='outside'):
        build_settings({'sfm.max_features': 10})
    with pytest.raises(StockpileError, match='expected int'):
        build_settings({'sfm.max_features': 'many'})
    with pytest.raises(StockpileError, match='expected bool'):
        build_settings({'compressed': 1})
    with pytest.raises(StockpileError, match='not one of'):
        build_settings({'segment.seed_order': 'random'})
    with pytest.raises(StockpileError, match='charuco'):
        build_settings({'recon.target': 'board'})
    # An int where a float is declared is fine.
    assert build_settings({'measure.specific_gravity': 3}).measure.specific_gravity == 3.0


def test_options_built_from_values() -> None:
    s = build_settings({'recon.target': 'charuco:5x4:0.08:0.06', 'poisson.depth': 8,
                        'gradation.spec_class': 'III', 'work_dir': '/tmp/x'})  # fmt: skip
    assert s.recon.target is not None and s.recon.target.squares_x == 5
    assert s.recon.poisson.depth == 8
    assert s.spec_class == 'III' and s.class_table is None
    assert s.work_dir == Path('/tmp/x')
    paper = build_settings({'segment.mode': 'paper'}).segment
    assert (paper.threshold, paper.exclude_ground) == (0.7, False)
    assert (
        build_settings({'segment.mode': 'paper', 'segment.threshold': 0.81}).segment.threshold
        == 0.81
    )


def test_config_file_names_every_parameter_in_a_section_of_a_node_declaring_it() -> None:
    import yaml

    data = yaml.safe_load(CONFIG.read_text())
    seen = set()
    for section, body in data.items():
        names = set(flatten(body['ros__parameters']))
        seen |= names
        if section != '/**':
            component = section.removeprefix('stockpile_')
            assert names <= {s.name for s in settings_for(component)}, section
    assert seen == {s.name for s in SETTINGS}
    build_settings(load_params_yaml(CONFIG))


def test_rendered_yaml_loads_back_to_the_defaults(tmp_path: Path) -> None:
    path = tmp_path / 'p.yaml'
    path.write_text(render_params_yaml())
    assert load_params_yaml(path) == defaults()
