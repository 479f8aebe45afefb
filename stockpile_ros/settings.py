"""One table of every tunable parameter, shared by the ROS 2 nodes and ``stockpile replay``.

The table is derived from the option dataclasses of the stages (their defaults and the
``Attributes:`` section of their docstrings) plus a few node-level settings. The nodes declare
exactly these parameters (dotted names such as ``sfm.max_features``, which is how ROS 2 spells
nested YAML); the replay reads the same names from the same ``config/stockpile.yaml``.
"""

from __future__ import annotations

import dataclasses
import difflib
import inspect
import re
import textwrap
import typing
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, TypeAlias

import yaml

from .errors import StockpileError
from .recon.dense import DenseOptions
from .recon.keyframes import SelectorOptions
from .recon.pipeline import ReconOptions
from .recon.scale import TargetSpec
from .recon.sfm import SfmOptions
from .recon.surface import PoissonOptions
from .segment.measure import MeasureParams
from .segment.segmentation import SegmentParams

__all__ = [
    'NODES',
    'NODE_NAMES',
    'SETTINGS',
    'Setting',
    'Settings',
    'build_settings',
    'defaults',
    'flatten',
    'load_params_yaml',
    'render_params_yaml',
    'settings_for',
]

Value: TypeAlias = bool | int | float | str

NODES = ('keyframes', 'reconstruction', 'segmentation')
"""The components; their ROS node names are ``stockpile_<component>``."""

NODE_NAMES = tuple(f'stockpile_{n}' for n in NODES)
"""ROS node names of the components (as in launch/stockpile.launch.py)."""


@dataclass(frozen=True)
class Setting:
    """One parameter.

    Attributes:
        name: Dotted name (``group.field``, or a bare name for node-level settings).
        default: Default value; its type is the parameter's type.
        description: What it does (from the dataclass docstring where it comes from one).
        nodes: Components that declare it.
        low: Smallest allowed value (numbers only).
        high: Largest allowed value (numbers only).
        choices: Allowed values of a string, empty when free.
        read_only: Fixed once a node has started.

    """

    name: str
    default: Value
    description: str
    nodes: tuple[str, ...]
    low: float | None = None
    high: float | None = None
    choices: tuple[str, ...] = ()
    read_only: bool = False

    def check(self, value: Any) -> Value:
        """Return ``value`` converted to this setting's type.

        Raises:
            StockpileError: Wrong type, outside the range, or not one of the choices.

        """
        kind = type(self.default)
        ok = isinstance(value, kind) and not (kind is int and isinstance(value, bool))
        if kind is float and isinstance(value, int) and not isinstance(value, bool):
            value, ok = float(value), True
        if not ok:
            raise StockpileError(f'parameter {self.name}: expected {kind.__name__}, got {value!r}')
        number = isinstance(value, (int, float)) and not isinstance(value, bool)
        if number and (
            (self.low is not None and value < self.low)
            or (self.high is not None and value > self.high)
        ):
            raise StockpileError(
                f'parameter {self.name}: {value} is outside [{self.low}, {self.high}]'
            )
        if self.choices and value not in self.choices:
            raise StockpileError(
                f'parameter {self.name}: {value!r} is not one of {", ".join(self.choices)}'
            )
        checked: Value = value
        return checked


# Ranges of every number in the table: [low, high].
_RANGES: dict[str, tuple[float, float]] = {
    'selector.work_width': (32, 4096),
    'selector.blur_ratio': (0.0, 1.0),
    'selector.reference_frames': (1, 1000),
    'selector.min_parallax': (0.0, 1.0),
    'selector.min_tracked': (0.0, 1.0),
    'selector.min_spacing': (1, 10000),
    'selector.max_spacing': (0, 100000),
    'selector.max_keyframes': (2, 10000),
    'selector.max_corners': (8, 10000),
    'sfm.max_image_size': (64, 16384),
    'sfm.max_features': (64, 65536),
    'sfm.overlap': (1, 1000),
    'sfm.num_threads': (-1, 256),
    'sfm.min_registered_fraction': (0.0, 1.0),
    'sfm.min_features': (0, 65536),
    'sfm.min_triangulation_angle': (0.0, 90.0),
    'sfm.log_level': (0, 3),
    'dense.work_width': (64, 16384),
    'dense.stride': (1, 64),
    'dense.pair_window': (1, 100),
    'dense.partners': (1, 8),
    'dense.target_baseline': (0.0, 10.0),
    'dense.check_window': (0, 100),
    'dense.min_agree': (0, 100),
    'dense.depth_tolerance': (0.0, 1.0),
    'dense.voxel': (0.0, 1e6),
    'dense.block_size': (1, 31),
    'poisson.depth': (4, 14),
    'poisson.density_quantile': (0.0, 0.9),
    'poisson.max_distance': (0.0, 1000.0),
    'poisson.margin': (0.0, 1.0),
    'poisson.target_faces': (0, 100_000_000),
    'poisson.threads': (0, 1024),
    'recon.crop_radius': (0.0, 100.0),
    'recon.odometry_tolerance': (0.0, 10.0),
    'segment.threshold': (-1.0, 2.0),
    'segment.normal_smoothing': (0, 100),
    'segment.ground_tolerance': (0.0, 10.0),
    'segment.ground_min_nz': (0.0, 1.0),
    'segment.min_region_fraction': (0.0, 1.0),
    'segment.min_region_faces': (0, 100_000_000),
    'segment.border_depth': (0.0, 10.0),
    'segment.border_min_edges': (0, 100_000_000),
    'segment.valley_depth': (0.0, 1.0),
    'segment.valley_radius': (1e-4, 1.0),
    'segment.split_depth': (0.0, 1.0),
    'segment.split_radius': (1e-4, 1.0),
    'segment.split_min_share': (0.0, 0.5),
    'measure.specific_gravity': (0.5, 10.0),
    'measure.min_faces': (0, 100_000_000),
    'measure.height_bins': (1, 1000),
    'measure.ground_contact': (0.0, 10.0),
    'measure.extent_trim': (0.0, 0.25),
    'auto_trigger_keyframes': (0, 100000),
    'coverage_full_parallax': (0.1, 1000.0),
    'display_max_faces': (1000, 100_000_000),
}

# Fields a parameter would make no sense for: chosen by the caller or not a scalar.
_SKIP = {'recon.topic', 'recon.selector', 'recon.sfm', 'recon.dense', 'recon.poisson'}


def _attribute_docs(cls: type) -> dict[str, str]:
    """Parse the ``Attributes:`` section of a Google-style class docstring."""
    doc = inspect.getdoc(cls) or ''
    out: dict[str, str] = {}
    section = doc.split('Attributes:', 1)[1] if 'Attributes:' in doc else ''
    name = None
    for line in section.splitlines():
        match = re.match(r'^ {4}(\w+): ?(.*)$', line)
        if match:
            name = match.group(1)
            out[name] = match.group(2).strip()
        elif name and line.startswith(' ' * 8):
            out[name] += ' ' + line.strip()
        elif line.strip():
            break
    return out


def _from_dataclass(group: str, cls: type, nodes: tuple[str, ...]) -> list[Setting]:
    docs = _attribute_docs(cls)
    hints = typing.get_type_hints(cls)
    default_obj = cls()
    out = []
    for fld in dataclasses.fields(cls):
        name = f'{group}.{fld.name}'
        if name in _SKIP:
            continue
        value = getattr(default_obj, fld.name)
        if group == 'recon' and fld.name == 'target':
            value = ''
        if not isinstance(value, (bool, int, float, str)):
            continue
        choices = tuple(typing.get_args(hints[fld.name]))
        if not all(isinstance(c, str) for c in choices):
            choices = ()
        low, high = _RANGES.get(name, (None, None))
        out.append(Setting(name, value, docs.get(fld.name, ''), nodes, low, high, choices))
    return out


def _table() -> tuple[Setting, ...]:
    kf, rc, sg = ('keyframes',), ('reconstruction',), ('segmentation',)
    rows = [
        Setting('work_dir', '/tmp/stockpile', 'Work folder (docs/formats.md): keyframes/, '
                'sparse/, dense/, mesh/ and result/', NODES, read_only=True),
        Setting('frame_id', 'stockpile', 'Frame of the results: gravity-aligned, z up, origin '
                'on the ground at the pile centre', NODES, read_only=True),
        Setting('compressed', True, 'Subscribe to <image>/compressed (sensor_msgs/'
                'CompressedImage) instead of the raw image', kf, read_only=True),
        Setting('coverage_full_parallax', 6.0, 'Without odometry, coverage is the summed '
                'parallax of the keyframes (in image widths) over this value', kf,
                *_RANGES['coverage_full_parallax']),
        Setting('auto_trigger_keyframes', 0, 'Reconstruct on its own once this many keyframes '
                'are held (0: only on the service or trigger topic)', rc,
                *_RANGES['auto_trigger_keyframes']),
        Setting('display_max_faces', 200000, 'Meshes with more faces are decimated for the '
                'mesh and rock markers (the result folder keeps the full mesh)', rc + sg,
                *_RANGES['display_max_faces']),
        Setting('gradation.spec_class', '', 'Riprap class to check the gradation against, '
                "from the class table ('' checks nothing)", sg),
        Setting('gradation.class_table', '', "Class table YAML ('' uses "
                'config/riprap_classes.yaml)', sg),
    ]  # fmt: skip
    rows += _from_dataclass('selector', SelectorOptions, kf)
    rows += _from_dataclass('sfm', SfmOptions, rc)
    rows += _from_dataclass('dense', DenseOptions, rc)
    rows += _from_dataclass('poisson', PoissonOptions, rc)
    rows += _from_dataclass('recon', ReconOptions, rc)
    rows += _from_dataclass('segment', SegmentParams, sg)
    rows += _from_dataclass('measure', MeasureParams, sg)
    return tuple(rows)


SETTINGS: tuple[Setting, ...] = _table()
"""Every parameter, node-level ones first."""

_BY_NAME = {s.name: s for s in SETTINGS}


def settings_for(node: str) -> list[Setting]:
    """Return the parameters component ``node`` (one of :data:`NODES`) declares."""
    if node not in NODES:
        raise StockpileError(f'unknown component {node!r}; choose from {", ".join(NODES)}')
    return [s for s in SETTINGS if node in s.nodes]


def defaults() -> dict[str, Value]:
    """Return every parameter's default by name."""
    return {s.name: s.default for s in SETTINGS}


@dataclass(frozen=True)
class Settings:
    """The option objects built from parameter values.

    Attributes:
        values: Every parameter's value by name (defaults filled in).
        recon: Options of the reconstruction stages (keyframe selection included).
        segment: Segmentation parameters.
        measure: Measurement parameters.
        work_dir: Work folder.
        frame_id: Result frame.
        spec_class: Riprap class to check, '' for none.
        class_table: Class table path, None for the default one.

    """

    values: dict[str, Value]
    recon: ReconOptions
    segment: SegmentParams
    measure: MeasureParams
    work_dir: Path
    frame_id: str
    spec_class: str
    class_table: Path | None


def _group(values: Mapping[str, Value], group: str) -> dict[str, Value]:
    prefix = group + '.'
    return {k[len(prefix) :]: v for k, v in values.items() if k.startswith(prefix)}


def build_settings(overrides: Mapping[str, Any] | None = None) -> Settings:
    """Check parameter values and build the option objects from them.

    ``segment.mode`` picks the preset (``paper`` or ``default``); the other ``segment.*`` values
    replace the preset's only where they differ from the table default, so that ``mode: paper``
    alone gives the published rule.

    Args:
        overrides: Values by dotted name; missing ones take their default.

    Raises:
        StockpileError: Unknown name, wrong type, value out of range, or bad target text.

    """
    values = defaults()
    for name, value in (overrides or {}).items():
        setting = _BY_NAME.get(name)
        if setting is None:
            close = difflib.get_close_matches(name, _BY_NAME, n=3)
            hint = f' (did you mean {", ".join(close)}?)' if close else ''
            raise StockpileError(f'unknown parameter {name!r}{hint}')
        values[name] = setting.check(value)
    recon = _group(values, 'recon')
    target_text = str(recon.pop('target'))
    options = ReconOptions(
        selector=SelectorOptions(**_group(values, 'selector')),  # type: ignore[arg-type]
        sfm=SfmOptions(**_group(values, 'sfm')),  # type: ignore[arg-type]
        dense=DenseOptions(**_group(values, 'dense')),  # type: ignore[arg-type]
        poisson=PoissonOptions(**_group(values, 'poisson')),  # type: ignore[arg-type]
        target=TargetSpec.parse(target_text) if target_text else None,
        **recon,  # type: ignore[arg-type]
    )
    seg_values = _group(values, 'segment')
    mode = str(seg_values.pop('mode'))
    changed = {k: v for k, v in seg_values.items() if v != _BY_NAME[f'segment.{k}'].default}
    segment = replace(SegmentParams.preset(mode), **changed)  # type: ignore[arg-type]
    table = str(values['gradation.class_table'])
    return Settings(
        values=values,
        recon=options,
        segment=segment,
        measure=MeasureParams(**_group(values, 'measure')),  # type: ignore[arg-type]
        work_dir=Path(str(values['work_dir'])),
        frame_id=str(values['frame_id']),
        spec_class=str(values['gradation.spec_class']),
        class_table=Path(table) if table else None,
    )


def flatten(tree: Mapping[str, Any], prefix: str = '') -> dict[str, Any]:
    """Flatten nested dicts to dotted names.

    Example: ``{'sfm': {'overlap': 8}}`` -> ``{'sfm.overlap': 8}``.
    """
    out: dict[str, Any] = {}
    for key, value in tree.items():
        name = f'{prefix}{key}'
        if isinstance(value, Mapping):
            out.update(flatten(value, name + '.'))
        else:
            out[name] = value
    return out


def _node_matches(section: str, nodes: Iterable[str]) -> bool:
    if section in ('/**', '**'):
        return True
    base = section.rstrip('/').rsplit('/', 1)[-1]
    return base in nodes


def load_params_yaml(path: str | Path, nodes: Iterable[str] = NODE_NAMES) -> dict[str, Any]:
    """Read a ROS 2 parameters file into one flat mapping.

    Sections ``/**`` and those naming one of ``nodes`` (with or without a namespace) are merged in
    file order; their ``ros__parameters`` are flattened to dotted names.

    Raises:
        StockpileError: The file is missing, not YAML, or not a ROS 2 parameters file.

    """
    file = Path(path)
    try:
        data = yaml.safe_load(file.read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise StockpileError(f'cannot read parameters file {file}: {exc}') from exc
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise StockpileError(f'{file}: expected node sections at the top level')
    wanted = tuple(nodes)
    out: dict[str, Any] = {}
    for section, body in data.items():
        if not _node_matches(str(section), wanted):
            continue
        params = body.get('ros__parameters') if isinstance(body, dict) else None
        if not isinstance(params, dict):
            raise StockpileError(f'{file}: section {section} has no ros__parameters mapping')
        out.update(flatten(params))
    return out


def _yaml_value(value: Value) -> str:
    text = yaml.safe_dump(value, default_flow_style=True).strip()
    return text.removesuffix('\n...').strip()


def render_params_yaml() -> str:
    """Render every parameter, with its default and description, as a ROS 2 parameters file.

    Parameters declared by more than one component go under ``/**``; the others under the one
    node that declares them (nested by group). This is how ``config/stockpile.yaml`` is written.
    """
    lines = [
        '# Parameters of the stockpile_ros nodes (ros2 launch stockpile_ros stockpile.launch.py',
        '# params_file:=...) and of `stockpile replay --params`. Generated from the table in',
        '# stockpile_ros/settings.py (render_params_yaml); ranges are checked on load.',
    ]
    sections: list[tuple[str, list[Setting]]] = [('/**', [s for s in SETTINGS if len(s.nodes) > 1])]
    for node, name in zip(NODES, NODE_NAMES, strict=True):
        sections.append((name, [s for s in SETTINGS if s.nodes == (node,)]))
    for section, rows in sections:
        lines += ['', f'{section}:', '  ros__parameters:']
        group = ''
        for row in rows:
            head, _, leaf = row.name.rpartition('.')
            if head != group:
                if head:
                    lines.append(f'    {head}:')
                group = head
            indent = '      ' if head else '    '
            note = row.description
            if row.low is not None:
                note += f' [{row.low:g}, {row.high:g}]'
            if row.choices:
                note += f' ({" | ".join(row.choices)})'
            lines += textwrap.wrap(note, 100, initial_indent=f'{indent}# ',
                                   subsequent_indent=f'{indent}#   ')  # fmt: skip
            lines.append(f'{indent}{leaf}: {_yaml_value(row.default)}')
    return '\n'.join(lines) + '\n'
