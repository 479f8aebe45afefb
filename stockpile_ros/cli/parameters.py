"""The parameter arguments of the measuring subcommands: ``--params``, ``--set`` and aliases.

Every value goes through the one table of :mod:`stockpile_ros.settings`: ``--params FILE`` reads a
ROS 2 parameters file (``config/stockpile.yaml`` is one), ``--set NAME=VALUE`` sets one parameter,
and the few convenience flags a subcommand keeps (``--target``, ``--mode``, ...) are aliases that
set one table key, and only when they are given. A flag or ``--set`` wins over the file; a flag
and a ``--set`` of the same key are refused. Every value is checked before any stage runs.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import StockpileError
from ..settings import Settings, Value, build_settings, check_value, get_setting, load_params_yaml

__all__ = ['Alias', 'add_parameter_arguments', 'add_run_arguments', 'settings_from_args']

# Namespace attribute the aliases record into: {table key: (flag, text or constant)}.
_ALIASED = 'aliased'


@dataclass(frozen=True)
class Alias:
    """A convenience flag that sets one table key, only when it is given.

    Attributes:
        flag: The option, e.g. ``--target``.
        name: The table key it sets, e.g. ``recon.target``.
        help: Its ``--help`` text (the key it sets is added).
        const: The value a flag without an argument sets (``--no-odometry`` sets False); None:
            the flag takes the value as its argument, read as ``--set`` reads it.
        metavar: Name of the argument in the help; None: the choices, or VALUE.
        required: The subcommand cannot run without it.

    """

    flag: str
    name: str
    help: str
    const: bool | None = None
    metavar: str | None = None
    required: bool = False


class _SetKey(argparse.Action):
    """Record ``--flag VALUE`` (or a constant for a flag alone) as one table key."""

    def __init__(self, option_strings: Sequence[str], dest: str, *, key: str, **kwargs: Any):
        self.key = key
        super().__init__(option_strings, dest, **kwargs)

    def __call__(
        self,
        parser: argparse.ArgumentParser,
        namespace: argparse.Namespace,
        values: str | Sequence[Any] | None,
        option_string: str | None = None,
    ) -> None:
        given = dict(getattr(namespace, self.dest) or {})
        given[self.key] = (option_string or self.option_strings[0],
                           self.const if self.nargs == 0 else values)  # fmt: skip
        setattr(namespace, self.dest, given)


def add_parameter_arguments(parser: argparse.ArgumentParser, aliases: Sequence[Alias] = ()) -> None:
    """Add ``--params``, ``--set`` and the ``aliases`` to ``parser``.

    Raises:
        StockpileError: An alias names a key the table does not have.

    """
    group = parser.add_argument_group(
        'parameters', 'those of the nodes (config/stockpile.yaml); a flag or --set beats --params'
    )
    group.add_argument('--params', type=Path, metavar='FILE',
                       help='ROS 2 parameters YAML, e.g. config/stockpile.yaml')  # fmt: skip
    group.add_argument('--set', action='append', default=[], metavar='NAME=VALUE',
                       help='set one parameter, e.g. sfm.overlap=10; repeatable')  # fmt: skip
    for alias in aliases:
        setting = get_setting(alias.name)
        shown = '' if alias.const is None else f'={str(alias.const).lower()}'
        # argparse formats help texts with %: a literal one must be doubled.
        text = f'{alias.help} (sets {alias.name}{shown})'.replace('%', '%%')
        if alias.const is not None:
            group.add_argument(alias.flag, action=_SetKey, dest=_ALIASED, key=alias.name,
                               nargs=0, const=alias.const, required=alias.required,
                               help=text)  # fmt: skip
            continue
        metavar = alias.metavar or ('{' + ','.join(setting.choices) + '}' if setting.choices
                                    else 'VALUE')  # fmt: skip
        group.add_argument(alias.flag, action=_SetKey, dest=_ALIASED, key=alias.name,
                           metavar=metavar, required=alias.required, help=text)  # fmt: skip


def add_run_arguments(parser: argparse.ArgumentParser, folder: str) -> None:
    """Add ``--resume`` and ``--fresh``: what to do with a ``folder`` that holds a run."""
    group = parser.add_mutually_exclusive_group()
    group.add_argument(
        '--resume',
        action='store_true',
        help=f'continue the run of the same input and parameters in {folder}',
    )
    group.add_argument('--fresh', action='store_true',
                       help=f'clear {folder} and start over')  # fmt: skip


def _assignment(item: str) -> tuple[str, Value]:
    name, sep, text = item.partition('=')
    name = name.strip()
    if not sep or not name:
        raise StockpileError(f'--set {item!r}: expected NAME=VALUE')
    try:
        return name, get_setting(name).parse(text)
    except StockpileError as exc:
        raise StockpileError(f'--set {item}: {exc}') from exc


def settings_from_args(args: argparse.Namespace) -> Settings:
    """Build the settings from ``--params``, the aliases and ``--set``, every value checked.

    Raises:
        StockpileError: The file cannot be read, a name is unknown, a value does not check
            (the message names the file or flag, the parameter, the value and what is allowed),
            or a flag and a ``--set`` set the same key.

    """
    values: dict[str, Value] = {}
    if args.params is not None:
        for name, value in load_params_yaml(args.params).items():
            try:
                values[name] = check_value(name, value)
            except StockpileError as exc:
                raise StockpileError(f'{args.params}: {exc}') from exc
    flags: dict[str, str] = {}
    for name, (flag, given) in (getattr(args, _ALIASED, None) or {}).items():
        setting = get_setting(name)
        try:
            values[name] = setting.parse(given) if isinstance(given, str) else setting.check(given)
        except StockpileError as exc:
            raise StockpileError(f'{flag}: {exc}') from exc
        flags[name] = flag
    for item in args.set:
        name, value = _assignment(item)
        if name in flags:
            raise StockpileError(f'{flags[name]} and --set {item} both set {name}; give one')
        values[name] = value
    return build_settings(values)
