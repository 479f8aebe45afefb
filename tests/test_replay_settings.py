"""The parameter table, the ROS 2 params YAML loader and the option objects built from them."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import pytest

from stockpile_ros.errors import StockpileError
from stockpile_ros.recon.scale import TargetSpec
from stockpile_ros.recon.sfm import SfmOptions
from stockpile_ros.settings import (
    EFFECTIVE_PARAMS,
    NODES,
    SETTINGS,
    build_settings,
    check_value,
    defaults,
    flatten,
    get_setting,
    load_params_yaml,
    render_params_yaml,
    settings_for,
    write_effective,
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
    # Choices come from the Literal type of the dataclass field.
    assert by_name['sfm.matcher'].choices == ('auto', 'sequential', 'exhaustive')
    assert by_name['sfm.mapper'].choices == ('incremental', 'global')
    assert by_name['measure.completion'].choices == ('auto', 'mirror', 'ground', 'hull')
    # Ranges come from the Range marker next to the field.
    assert (by_name['sfm.overlap'].low, by_name['sfm.overlap'].high) == (1, 1000)
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
    assert isinstance(s.recon.target[0], TargetSpec) and s.recon.target[0].squares_x == 5
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


def test_config_file_is_the_rendered_table() -> None:
    # Regenerate after changing a field: .venv/bin/python -c "from stockpile_ros.settings import
    # render_params_yaml as r; print(r(), end='')" > config/stockpile.yaml
    assert CONFIG.read_text() == render_params_yaml()


def test_an_explicit_segment_value_wins_over_the_preset_even_when_it_is_the_default() -> None:
    s = build_settings({'segment.mode': 'paper', 'segment.threshold': 0.93})
    assert s.segment.threshold == 0.93
    # The rest of the paper preset still applies, and values hold what the run uses.
    assert s.segment.exclude_ground is False and s.values['segment.exclude_ground'] is False
    assert s.explicit == {'segment.mode', 'segment.threshold'}
    # A caller passing every value (a node) names the explicit ones.
    every = {**defaults(), 'segment.mode': 'paper'}
    assert build_settings(every, explicit=['segment.mode']).segment.threshold == 0.7
    assert build_settings(every).segment.threshold == 0.93
    with pytest.raises(ValueError, match=r'segment\.threshold'):
        build_settings({'segment.mode': 'paper'}, explicit=['segment.threshold'])


@pytest.mark.parametrize('bad', [math.nan, math.inf, -math.inf])
def test_every_float_setting_refuses_nan_and_infinity(bad: float) -> None:
    floats = [s for s in SETTINGS if isinstance(s.default, float)]
    assert len(floats) > 20
    for s in floats:
        with pytest.raises(StockpileError, match=rf'parameter {s.name}: .* not a finite number'):
            check_value(s.name, bad)
        with pytest.raises(StockpileError, match='not a finite number'):
            build_settings({s.name: bad})


def test_check_value_names_the_parameter_the_value_and_what_is_allowed() -> None:
    with pytest.raises(StockpileError) as info:
        check_value('sfm.matcher', 'bogus')
    assert (
        str(info.value)
        == "parameter sfm.matcher: 'bogus' is not one of auto, sequential, exhaustive"
    )
    with pytest.raises(StockpileError, match=r'selector.blur_ratio: 1.5 is outside \[0, 1\]'):
        check_value('selector.blur_ratio', 1.5)
    with pytest.raises(StockpileError, match=r'recon\.target: .*at least 2 x 2 squares'):
        check_value('recon.target', 'charuco:1x1:0.08:0.06')
    with pytest.raises(StockpileError, match=r"unknown parameter 'sfm\.matcherr'"):
        check_value('sfm.matcherr', 'exhaustive')
    assert check_value('measure.specific_gravity', 3) == 3.0
    assert check_value('recon.target', '') == ''


def test_command_line_text_is_read_as_the_setting_type() -> None:
    assert get_setting('segment.threshold').parse('1e-1') == 0.1
    assert get_setting('sfm.use_camera_info').parse('false') is False
    assert get_setting('sfm.overlap').parse('12') == 12
    # A string setting keeps the text: YAML would read 1:20 as the base-60 number 80.
    assert get_setting('sfm.vocab_tree').parse('1:20') == '1:20'
    for text in ('.nan', 'nan', 'inf', '-.inf'):
        with pytest.raises(StockpileError, match='not a finite number'):
            get_setting('segment.threshold').parse(text)
    with pytest.raises(StockpileError, match='expected int'):
        get_setting('sfm.overlap').parse('many')


def test_an_unknown_riprap_class_is_refused_on_load() -> None:
    with pytest.raises(StockpileError, match=r"gradation\.spec_class: 'XI' is not one of I, II"):
        build_settings({'gradation.spec_class': 'XI'})
    assert build_settings({'gradation.spec_class': 'III'}).spec_class == 'III'


def test_effective_parameters_load_back_to_the_same_options(tmp_path: Path) -> None:
    given = {'segment.mode': 'paper', 'segment.threshold': 0.93, 'sfm.matcher': 'exhaustive',
             'recon.target': 'charuco:5x4:0.08:0.06:DICT_4X4_50'}  # fmt: skip
    settings = build_settings(given)
    path = write_effective(settings, tmp_path / 'work')
    assert path == tmp_path / 'work' / EFFECTIVE_PARAMS
    text = path.read_text()
    marked = {line.split(':')[0].strip() for line in text.splitlines()
              if line.endswith('  # set explicitly')}  # fmt: skip
    assert marked == {'mode', 'threshold', 'matcher', 'target'}
    assert '# Set explicitly: recon.target, segment.mode, segment.threshold, sfm.matcher' in text
    again = build_settings(load_params_yaml(path))
    assert (again.recon, again.segment, again.measure) == (
        settings.recon,
        settings.segment,
        settings.measure,
    )
    # The preset's values are written as used: paper leaves the ground in the search.
    assert load_params_yaml(path)['segment.exclude_ground'] is False
    # A moved work folder is what the file records.
    moved = dataclasses.replace(settings, work_dir=tmp_path / 'elsewhere')
    assert load_params_yaml(write_effective(moved, tmp_path))['work_dir'] == str(
        tmp_path / 'elsewhere'
    )
    assert not list(tmp_path.glob('*.partial'))


def test_effective_parameters_from_values_and_a_folder_that_cannot_be_made(tmp_path: Path) -> None:
    path = write_effective({'sfm.overlap': 5}, tmp_path)
    assert load_params_yaml(path)['sfm.overlap'] == 5
    blocker = tmp_path / 'file'
    blocker.write_text('')
    with pytest.raises(StockpileError, match=f'cannot write {blocker}/params.yaml'):
        write_effective(build_settings(), blocker)
