"""Command-line flags for the estimator options (the node declares the same OPTIONS as parameters):
``--preset`` and the user options in one group, the expert knobs in an "advanced" group."""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from typing import Any

from ..core.errors import GaitEstimatorError
from ..core.options import OPTIONS, PRESETS, RESAMPLE_MODES, EstimatorConfig, Option


def _add_flag(group: Any, opt: Option) -> None:
    flag = "--" + opt.name.replace("_", "-")
    if opt.name == "resample":
        group.add_argument(flag, dest=opt.name, nargs="?", const="on", choices=RESAMPLE_MODES, help=opt.description)
    elif isinstance(opt.default, bool):
        group.add_argument(flag, dest=opt.name, action=argparse.BooleanOptionalAction, default=None,
                           help=opt.description)
    elif isinstance(opt.default, list):
        kind = float if isinstance(opt.default[0], float) else str
        group.add_argument(flag, dest=opt.name, nargs="+", type=kind, metavar="V", help=opt.description)
    else:
        group.add_argument(flag, dest=opt.name, type=type(opt.default), metavar="V", help=opt.description)


def add_estimator_arguments(parser: argparse.ArgumentParser, skip: Sequence[str] = ("max_gap_s",)) -> None:
    """Add ``--preset`` and one flag per OPTIONS entry not in ``skip`` to ``parser``, the
    advanced ones in their own group; absent flags take the preset's value."""
    group = parser.add_argument_group("estimator options (default: the 'default' preset)")
    group.add_argument("--preset", choices=tuple(PRESETS), default="default",
                       help="option values to start from: default (robust for a new wearer) or paper (the paper's "
                       "algorithm, reproduces the reference implementation); the flags override it")
    advanced = parser.add_argument_group("advanced estimator options (docs/options.md)")
    for opt in OPTIONS:
        if opt.name not in skip:
            _add_flag(advanced if opt.advanced else group, opt)


def config_from_args(args: Any, **overrides: Any) -> EstimatorConfig:
    """EstimatorConfig from parsed flags: the ``--preset``'s values, then the flags given, then
    ``overrides`` (None values ignored); a bad value: GaitEstimatorError naming the option."""
    values: dict[str, Any] = {}
    for opt in OPTIONS:
        v = getattr(args, opt.name, None)
        if v is not None:
            values[opt.name] = tuple(v) if isinstance(v, list) else v
    values.update({k: v for k, v in overrides.items() if v is not None})
    try:
        return EstimatorConfig.preset(getattr(args, "preset", None) or "default", **values)
    except ValueError as exc:
        raise GaitEstimatorError(str(exc)) from None
