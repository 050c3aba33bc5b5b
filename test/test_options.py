"""Each option's default is written once, in ``EstimatorConfig``: ``OPTIONS``, the stage
parameters, the readers, ``config/estimator.yaml`` and the docs' tables agree with it."""

from __future__ import annotations

import re
from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest
import yaml

from gait_estimator.core.channels import CHANNELS
from gait_estimator.core.options import ADVANCED, OPTIONS, EstimatorConfig
from gait_estimator.core.pipeline import PipelineParams
from gait_estimator.core.stamps import StreamGuard
from gait_estimator.io.read_options import ReadOptions

REPO = Path(__file__).resolve().parents[1]


def test_options_are_the_config_fields():
    assert [o.name for o in OPTIONS] == [f.name for f in fields(EstimatorConfig)]
    config = EstimatorConfig()
    for o in OPTIONS:
        value = getattr(config, o.name)
        assert (list(value) if isinstance(value, tuple) else value) == o.default, o.name


def test_stage_parameters_and_readers_default_to_the_options():
    """A stage parameter built without arguments is the one ``from_config`` makes of the defaults."""
    stages = PipelineParams.from_config(EstimatorConfig())
    for name in ("gaps", "match", "supervisor", "calibration", "adapt"):
        params = getattr(stages, name)
        assert params == type(params)(), name
    assert ReadOptions().max_gap_s == StreamGuard().max_gap_s == EstimatorConfig().max_gap_s


def test_config_yaml_holds_the_option_defaults():
    params = yaml.safe_load((REPO / "config" / "estimator.yaml").read_text(encoding="utf-8"))["/**"]["ros__parameters"]
    for o in OPTIONS:
        assert (params["advanced"] if o.advanced else params)[o.name] == o.default, o.name
    assert set(params["advanced"]) == ADVANCED


def _cell_value(text: str):
    """A docs table's default cell as a value: `text` (a string; `''` empty), YAML, 'all four'
    (channels) or 'a … b in c steps'."""
    text = text.strip()
    if text.startswith("`"):
        return text.strip("`").replace("''", "")
    if text == "all four":
        return list(CHANNELS)
    steps = re.fullmatch(r"([\d.]+) … ([\d.]+) in ([\d.]+) steps", text)
    if steps:
        a, b, c = map(float, steps.groups())
        return np.round(np.arange(a, b + c / 2, c), 6).tolist()
    return yaml.safe_load(text)


def _table(path: Path, header: str) -> dict[str, tuple[object, object]]:
    """Rows of the table under ``header``: option name -> (default, paper value)."""
    lines = path.read_text(encoding="utf-8").splitlines()
    start = lines.index(header) + 2
    rows = {}
    for line in lines[start:]:
        if not line.startswith("| `"):
            break
        name, default = (c.strip() for c in line.split("|")[1:3])
        m = re.fullmatch(r"(.*?)(?: \((.*)\))?", default)
        value = _cell_value(m.group(1))
        rows[name.strip("`")] = (value, value if m.group(2) is None else _cell_value(m.group(2)))
    return rows


@pytest.mark.parametrize(("doc", "first", "advanced"), [("README.md", "option", False), ("docs/options.md", "name", True)])
def test_docs_tables_hold_the_option_defaults(doc, first, advanced):
    rows = _table(REPO / doc, f"| {first} | default (`paper`) | meaning, units |")
    rows.pop("preset", None)
    assert list(rows) == [o.name for o in OPTIONS if o.advanced == advanced]
    for o in OPTIONS:
        if o.advanced == advanced:
            assert rows[o.name] == (o.default, o.paper_value), o.name


@pytest.mark.parametrize("margin", [-0.1, 1.0, float("nan"), True, "0.2"])
def test_switch_back_margin_is_below_one(margin):
    with pytest.raises(ValueError, match="switch_back_margin"):
        EstimatorConfig(switch_back_margin=margin)
