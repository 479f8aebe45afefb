"""One table of every tunable parameter, shared by the ROS 2 nodes and the ``stockpile`` commands.

The table is derived from the option dataclasses of the stages plus a few node-level settings.
Each field carries its type (``Literal[...]`` for a choice), its default, its range (a
:class:`~stockpile_ros.ranges.Range` in ``Annotated``) and, in the ``Attributes:`` section of the
class docstring, its description. The nodes declare exactly these parameters (dotted names such as
``sfm.max_features``, which is how ROS 2 spells nested YAML); ``stockpile reconstruct``,
``segment`` and ``replay`` read the same names from the same files (``--params``, ``--set``).

Every value is checked when it is loaded (:func:`check_value`: type, finite, range, choice, target
spec), before any stage runs; :func:`write_effective` records the values a run used.
"""

from __future__ import annotations

import contextlib
import dataclasses
import difflib
import inspect
import math
import re
import textwrap
import typing
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any, Literal, TypeAlias

import yaml

from .cloud.level import parse_up
from .cloud.mesh import CloudOptions
from .errors import StockpileError
from .ranges import Range
from .recon.dense import DenseOptions
from .recon.keyframes import SelectorOptions
from .recon.options import ReconOptions
from .recon.scale import parse_targets
from .recon.sfm import SfmOptions
from .recon.surface import PoissonOptions
from .segment.gradation import load_class_table
from .segment.measure import MeasureParams
from .segment.params import SegmentParams, asked_min_rock_b
from .segment.qa import ReportOptions

__all__ = [
    'EFFECTIVE_PARAMS',
    'NODES',
    'NODE_NAMES',
    'SETTINGS',
    'Setting',
    'Settings',
    'build_settings',
    'check_value',
    'class_spec',
    'defaults',
    'flatten',
    'get_setting',
    'load_params_yaml',
    'render_params_yaml',
    'settings_for',
    'smallest_rock_asked',
    'write_effective',
]

Value: TypeAlias = bool | int | float | str

NODES = ('keyframes', 'reconstruction', 'segmentation')
"""The components; their ROS node names are ``stockpile_<component>``."""

NODE_NAMES = tuple(f'stockpile_{n}' for n in NODES)
"""ROS node names of the components (as in launch/stockpile.launch.py)."""

EFFECTIVE_PARAMS = 'params.yaml'
"""File name :func:`write_effective` writes into a work or result folder."""


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
        parse_text: Checks a non-empty string value further (the target spec), raising
            StockpileError with the reason.

    """

    name: str
    default: Value
    description: str
    nodes: tuple[str, ...]
    low: float | None = None
    high: float | None = None
    choices: tuple[str, ...] = ()
    read_only: bool = False
    parse_text: Callable[[str], object] | None = field(default=None, compare=False, repr=False)

    def _allowed(self) -> str:
        if self.low is not None and self.high is not None:
            return f'[{self.low:g}, {self.high:g}]'
        return 'a finite number'

    def check(self, value: Any) -> Value:
        """Return ``value`` converted to this setting's type (an int is taken for a float).

        Raises:
            StockpileError: Wrong type, not finite, outside the range, not one of the choices, or
                a target spec that does not parse; the message names the parameter, the value and
                what is allowed.

        """
        kind = type(self.default)
        if kind is float and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        if not isinstance(value, kind) or (kind is int and isinstance(value, bool)):
            raise StockpileError(f'parameter {self.name}: expected {kind.__name__}, got {value!r}')
        if isinstance(value, float) and not math.isfinite(value):
            raise StockpileError(
                f'parameter {self.name}: {value} is not a finite number (allowed: '
                f'{self._allowed()})'
            )
        # Written as one chained comparison so that nothing unordered can slip through it.
        if (
            isinstance(value, (int, float))
            and not isinstance(value, bool)
            and self.low is not None
            and self.high is not None
            and not self.low <= value <= self.high
        ):
            raise StockpileError(f'parameter {self.name}: {value} is outside {self._allowed()}')
        if self.choices and value not in self.choices:
            raise StockpileError(
                f'parameter {self.name}: {value!r} is not one of {", ".join(self.choices)}'
            )
        if self.parse_text is not None and isinstance(value, str) and value:
            try:
                self.parse_text(value)
            except StockpileError as exc:
                raise StockpileError(f'parameter {self.name}: {exc}') from exc
        checked: Value = value
        return checked

    def parse(self, text: str) -> Value:
        """Return the value command-line ``text`` gives this setting, checked.

        A string setting takes the text as it is; the others read it as a YAML scalar (``true``,
        ``8``, ``.nan``), a float also as Python writes it (``1e-3``, ``nan``, ``inf``).

        Raises:
            StockpileError: As :meth:`check`.

        """
        if isinstance(self.default, str):
            return self.check(text)
        value: Any
        try:
            value = yaml.safe_load(text)
        except yaml.YAMLError:
            value = text
        if isinstance(self.default, float) and isinstance(value, str):
            with contextlib.suppress(ValueError):
                value = float(value)
        return self.check(value)


# Fields a parameter would make no sense for: chosen by the caller or not a scalar.
_SKIP = {'recon.topic', 'recon.selector', 'recon.sfm', 'recon.dense', 'recon.poisson'}

# Strings whose content is checked beyond their type when they are loaded.
_TEXT_CHECKS: dict[str, Callable[[str], object]] = {
    'recon.target': parse_targets,
    'cloud.up': parse_up,
}


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
    hints = typing.get_type_hints(cls, include_extras=True)
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
        hint = hints[fld.name]
        low = high = None
        if typing.get_origin(hint) is Annotated:
            hint, *marks = typing.get_args(hint)
            for mark in marks:
                if isinstance(mark, Range):
                    low, high = mark.low, mark.high
        choices = typing.get_args(hint) if typing.get_origin(hint) is Literal else ()
        out.append(Setting(name, value, docs.get(fld.name, ''), nodes, low, high,
                           tuple(str(c) for c in choices),
                           parse_text=_TEXT_CHECKS.get(name)))  # fmt: skip
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
                'parallax of the keyframes (in image widths) over this value', kf, 0.1, 1000.0),
        Setting('auto_trigger_keyframes', 0, 'Reconstruct on its own once this many keyframes '
                'are held (0: only on the service or trigger topic)', rc, 0, 100000),
        Setting('display_max_faces', 200000, 'Meshes with more faces are decimated for the '
                'mesh and rock markers (the result folder keeps the full mesh)', rc + sg,
                1000, 100_000_000),
        Setting('gradation.spec_class', '', 'Riprap class to check the gradation against, '
                "from the class table ('' checks nothing)", sg),
        Setting('gradation.class_table', '', "Class table YAML ('' uses "
                'config/riprap_classes.yaml)', sg),
    ]  # fmt: skip
    rows += _from_dataclass('selector', SelectorOptions, kf)
    rows += _from_dataclass('sfm', SfmOptions, rc)
    rows += _from_dataclass('dense', DenseOptions, rc)
    rows += _from_dataclass('poisson', PoissonOptions, rc)
    # The keyframe node reads two reconstruction options: whether odometry is used (its
    # keyframes then wait for it) and how large an image may be.
    shared = ('recon.use_odometry', 'recon.max_image_pixels')
    rows += [dataclasses.replace(r, nodes=kf + rc) if r.name in shared else r
             for r in _from_dataclass('recon', ReconOptions, rc)]  # fmt: skip
    rows += _from_dataclass('cloud', CloudOptions, rc)
    rows += _from_dataclass('segment', SegmentParams, sg)
    rows += _from_dataclass('measure', MeasureParams, sg)
    rows += _from_dataclass('report', ReportOptions, sg)
    return tuple(rows)


SETTINGS: tuple[Setting, ...] = _table()
"""Every parameter, node-level ones first."""

_BY_NAME = {s.name: s for s in SETTINGS}


def get_setting(name: str) -> Setting:
    """Return the parameter called ``name``.

    Raises:
        StockpileError: No parameter has that name (the message suggests close ones).

    """
    setting = _BY_NAME.get(name)
    if setting is None:
        close = difflib.get_close_matches(name, _BY_NAME, n=3)
        hint = f' (did you mean {", ".join(close)}?)' if close else ''
        raise StockpileError(f'unknown parameter {name!r}{hint}')
    return setting


def check_value(name: str, value: object) -> Value:
    """Check one parameter value, as on load and on every change of a node's parameter.

    Args:
        name: Dotted parameter name, e.g. ``segment.threshold``.
        value: The new value (YAML or ROS parameter types; an int is taken for a float).

    Returns:
        The value converted to the parameter's type.

    Raises:
        StockpileError: Unknown name, wrong type, NaN or infinite, outside the range, not one of
            the choices, or a target spec that does not parse. The message names the parameter,
            the value and what is allowed.

    """
    return get_setting(name).check(value)


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
        values: Every parameter's effective value by name: defaults filled in, and the
            ``segment`` values as the preset of ``segment.mode`` and the explicit ones give them.
        explicit: Names of the parameters that were set explicitly.
        recon: Options of the reconstruction stages (keyframe selection included).
        cloud: How a point cloud becomes the mesh (a file, or a PointCloud2 stream).
        segment: Segmentation parameters.
        measure: Measurement parameters.
        work_dir: Work folder.
        frame_id: Result frame.
        spec_class: Riprap class to check, '' for none.
        class_table: Class table path, None for the default one.

    """

    values: dict[str, Value]
    explicit: frozenset[str]
    recon: ReconOptions
    cloud: CloudOptions
    segment: SegmentParams
    measure: MeasureParams
    work_dir: Path
    frame_id: str
    spec_class: str
    class_table: Path | None


def _group(values: Mapping[str, Value], group: str) -> dict[str, Value]:
    prefix = group + '.'
    return {k[len(prefix) :]: v for k, v in values.items() if k.startswith(prefix)}


def build_settings(
    overrides: Mapping[str, Any] | None = None, *, explicit: Iterable[str] | None = None
) -> Settings:
    """Check parameter values and build the option objects from them.

    ``segment.mode`` picks the preset (``paper`` or ``default``); the ``segment`` values set
    explicitly replace the preset's, whatever they are (0.93 with ``mode: paper`` is 0.93), and
    the others come from the preset, so that ``mode: paper`` alone gives the published rule.

    Args:
        overrides: Values by dotted name; missing ones take their default.
        explicit: The names among ``overrides`` that were set explicitly, when ``overrides``
            also holds values that are only defaults (a node passes every declared parameter);
            None: every name in ``overrides``.

    Raises:
        StockpileError: Unknown name, wrong type, value not finite, out of range or not one of
            the choices, a target spec that does not parse, or a riprap class the class table
            does not have.
        ValueError: ``explicit`` names a parameter that ``overrides`` has no value for.

    """
    given = dict(overrides or {})
    named = frozenset(given if explicit is None else explicit)
    if not named <= given.keys():
        raise ValueError(
            f'explicit names without a value: {", ".join(sorted(named - given.keys()))}'
        )
    values = defaults()
    for name, value in given.items():
        values[name] = check_value(name, value)
    recon = _group(values, 'recon')
    target_text = str(recon.pop('target'))
    options = ReconOptions(
        selector=SelectorOptions(**_group(values, 'selector')),  # type: ignore[arg-type]
        sfm=SfmOptions(**_group(values, 'sfm')),  # type: ignore[arg-type]
        dense=DenseOptions(**_group(values, 'dense')),  # type: ignore[arg-type]
        poisson=PoissonOptions(**_group(values, 'poisson')),  # type: ignore[arg-type]
        target=parse_targets(target_text),
        **recon,  # type: ignore[arg-type]
    )
    seg_values = _group(values, 'segment')
    mode = seg_values.pop('mode')
    chosen = {k: v for k, v in seg_values.items() if f'segment.{k}' in named}
    segment = SegmentParams.preset(mode, **chosen)  # type: ignore[arg-type]
    values.update({f'segment.{k}': getattr(segment, k) for k in seg_values})
    table = str(values['gradation.class_table'])
    class_table = Path(table) if table else None
    spec_class = str(values['gradation.spec_class'])
    if spec_class:
        known = load_class_table(class_table)['classes']
        if spec_class not in known:
            raise StockpileError(
                f'parameter gradation.spec_class: {spec_class!r} is not one of '
                f'{", ".join(known)} (the classes of {table or "config/riprap_classes.yaml"})'
            )
    return Settings(
        values=values,
        explicit=named,
        recon=options,
        cloud=CloudOptions(**_group(values, 'cloud')),  # type: ignore[arg-type]
        segment=segment,
        measure=MeasureParams(**_group(values, 'measure')),  # type: ignore[arg-type]
        work_dir=Path(str(values['work_dir'])),
        frame_id=str(values['frame_id']),
        spec_class=spec_class,
        class_table=class_table,
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


_CONFIG_HEADER = (
    '# Parameters of the stockpile_ros nodes (ros2 launch stockpile_ros stockpile.launch.py',
    '# params_file:=...) and of `stockpile reconstruct|segment|replay --params`. Generated from',
    '# the table in stockpile_ros/settings.py (render_params_yaml); values are checked on load.',
)


def _render(values: Mapping[str, Value], explicit: Iterable[str], header: Iterable[str]) -> str:
    """Render ``values`` as a ROS 2 parameters file with the descriptions as comments."""
    marked = set(explicit)
    lines = list(header)
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
            mark = '  # set explicitly' if row.name in marked else ''
            lines.append(f'{indent}{leaf}: {_yaml_value(values[row.name])}{mark}')
    return '\n'.join(lines) + '\n'


def render_params_yaml() -> str:
    """Render every parameter, with its default and description, as a ROS 2 parameters file.

    Parameters declared by more than one component go under ``/**``; the others under the one
    node that declares them (nested by group). This is how ``config/stockpile.yaml`` is written.
    """
    return _render(defaults(), (), _CONFIG_HEADER)


def write_effective(settings: Settings | Mapping[str, Any], folder: str | Path) -> Path:
    """Write the parameters a run uses into ``folder`` as :data:`EFFECTIVE_PARAMS`.

    The file is a ROS 2 parameters file like ``config/stockpile.yaml`` (``--params`` or a launch
    ``params_file`` reads it back to the same options), holding every parameter's effective value;
    the line of each one set explicitly ends in ``# set explicitly`` and the header lists them. It
    is written beside and renamed into place, so a reader never sees half of it.

    Args:
        settings: The settings of the run, or parameter values to build them from (every one of
            them explicit).
        folder: Work or result folder (created when missing).

    Returns:
        The path written.

    Raises:
        StockpileError: The values do not check (see :func:`build_settings`), or the file cannot
            be written (the message names the path and the fault).

    """
    built = settings if isinstance(settings, Settings) else build_settings(settings)
    # Callers point a run at another folder with dataclasses.replace(settings, work_dir=...)
    # (the replay, the segmentation node): the field is what the run uses, not values.
    values = {**built.values, 'work_dir': str(built.work_dir)}
    explicit = sorted(built.explicit)
    header = [
        '# Effective parameters of a stockpile_ros run (docs/formats.md): every value it used, in',
        '# the format of config/stockpile.yaml; pass this file to --params to run it again.',
        *textwrap.wrap(
            'Set explicitly: ' + (', '.join(explicit) or 'none (every value is the default)'),
            100, initial_indent='# ', subsequent_indent='#   ',
        ),
    ]  # fmt: skip
    path = Path(folder) / EFFECTIVE_PARAMS
    partial = path.with_name(path.name + '.partial')
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        partial.write_text(_render(values, explicit, header))
        partial.replace(path)
    except OSError as exc:
        raise StockpileError(f'cannot write {path}: {exc.strerror or exc}') from exc
    return path


def class_spec(settings: Settings) -> dict[str, Any] | None:
    """Return the riprap class ``settings`` checks, from its class table; None when none.

    :func:`build_settings` has checked that the table holds the class.
    """
    if not settings.spec_class:
        return None
    spec: dict[str, Any] = load_class_table(settings.class_table)['classes'][settings.spec_class]
    return spec


def smallest_rock_asked(settings: Settings) -> float:
    """Return the smallest rock of interest asked for: segment.min_rock_b, else the class's [m].

    0 when neither is given (the mesh's own floor is then the smallest rock).
    """
    asked = asked_min_rock_b(settings.segment, class_spec(settings))
    return 0.0 if asked is None else asked[1]
