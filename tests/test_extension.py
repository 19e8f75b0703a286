"""Adding an analysis is one module and no other edit: a module dropped into
estim/experiments/ is found by the registry, validated, run, written and listed like the
shipped ones (docs/extending.md, "Adding an analysis")."""

from pathlib import Path

import pandas as pd
import yaml
from click.testing import CliRunner

import estim.experiments
from estim.cli.main import main
from estim.config.registry import ANALYSES

NAME = "sample_mean_extension_test"

MODULE = '''"""A sample mean of normal draws: the smallest analysis."""

from __future__ import annotations

from dataclasses import dataclass

import pandas as pd

from estim.config.settings import number
from estim.config.settings import Settings, block, setting, settings_class
from estim.experiments.base import Result
from estim.experiments.shared.blocks import MonteCarlo
from estim.reference.tablespec import TableSpec


@settings_class
class Config(Settings):
    """Draws of N(mean, 1)."""

    mean: float = setting(0.0, number(minimum=-10.0, maximum=10.0), doc="the mean")
    monte_carlo: MonteCarlo = block(MonteCarlo, required=True, doc="runs and seed")


SCHEMA = Config.schema()
TABLES = {"means": TableSpec("means.csv", ("mean",), ("sample_mean", "runs"))}


@dataclass(frozen=True)
class Plan:
    config: Config


def prepare(config, source):
    return Plan(config)


def work_units(exp):
    return 1


def work_size(config):
    return config.monte_carlo.runs


def tiny(config):
    return {"monte_carlo.runs": 2}


def run(exp, jobs=1, on_done=None):
    mc = exp.config.monte_carlo
    draws = exp.config.mean + mc.rng(0).standard_normal(mc.runs)
    if on_done:
        on_done()
    row = {"mean": exp.config.mean, "sample_mean": float(draws.mean()), "runs": mc.runs}
    return Result(tables={"means": pd.DataFrame([row])})


def printout(result):
    return result.tables["means"].to_string(index=False)
'''


def test_an_analysis_is_one_module_the_registry_finds(tmp_path):
    module = Path(estim.experiments.__file__).parent / f"{NAME}.py"
    module.write_text(MODULE)
    try:
        assert NAME in ANALYSES
        config = tmp_path / "draws.yaml"
        config.write_text(yaml.safe_dump({"analysis": NAME, "mean": 2.0,
                                          "monte_carlo": {"runs": 400, "seed": 1}}))
        done = CliRunner().invoke(main, ["run", str(config), "--out", str(tmp_path / "out"),
                                         "--quiet"])
        assert done.exit_code == 0, done.output
        table = pd.read_csv(tmp_path / "out" / "draws" / "means.csv")
        assert table["runs"].tolist() == [400]
        assert abs(table["sample_mean"].iloc[0] - 2.0) < 4 / 400 ** 0.5     # 4 sigma
        wrong = tmp_path / "wrong.yaml"
        wrong.write_text(yaml.safe_dump({"analysis": NAME, "mean": 20.0,
                                         "monte_carlo": {"runs": 4, "seed": 1}}))
        refused = CliRunner().invoke(main, ["validate", str(wrong)])
        assert refused.exit_code == 2 and "mean" in refused.output, refused.output
    finally:
        module.unlink()
    assert NAME not in ANALYSES
