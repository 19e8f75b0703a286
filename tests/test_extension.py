"""Adding an analysis is one module and no other edit: a module dropped into
estim/experiments/ is found by the registry, validated, run, written and listed like the
shipped ones (docs/extending.md, "Adding an analysis")."""

from pathlib import Path

import pandas as pd
import pytest
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


# slow: it writes a module into estim's own experiments folder for a few seconds, where
# test_analyses (in the default run, on another worker) would find an analysis without a
# shipped config; the slow run holds no test that lists every analysis
@pytest.mark.slow
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


RANDOM_FILTER = '''
import numpy as np

from estim.config.settings import number, setting, settings_class
from estim.estimators.base import Estimate, Estimator


@settings_class
class Dithered(Estimator, name="dithered"):
    """The measurement plus noise of its own: a filter that draws random numbers."""

    sigma: float = setting(1e-3, number(positive=True), doc="the dither")

    @classmethod
    def example(cls, model):
        return cls()

    def measured(self, model):
        return model.n_outputs

    def run(self, model, z, u, dt, x0=None, rng=None):
        if not isinstance(rng, np.random.Generator):
            raise TypeError(f"no generator: {rng!r}")
        y = z + self.sigma * rng.standard_normal(z.shape)
        return Estimate(y_hat=y, innovation=np.zeros_like(z),
                        broken=np.zeros(z.shape[0], bool))
'''


def test_an_estimator_that_takes_rng_gets_a_generator_of_its_own(tmp_path):
    """An estimator whose run takes ``rng`` gets a numpy Generator from the work unit's seed
    (estim.estimators.base.GENERATOR_KEY): the tables repeat byte for byte under --jobs 1
    and 2 and under another run, differ with the seed, and the filters that take none run
    as before (their rows equal those of a config without the plugin)."""
    import re

    root = Path(__file__).resolve().parents[1]
    blocks = re.findall(r"```(\w+)\n(.*?)```", (root / "docs" / "your-circuit.md").read_text(),
                        re.S)
    (tmp_path / "rectifier.cir").write_text(blocks[0][1])
    (tmp_path / "dithered.py").write_text(RANDOM_FILTER)
    plain = blocks[1][1].replace("frequencies_hz: [50]", "frequencies_hz: [50, 100]")
    (tmp_path / "plain.yaml").write_text(plain)
    (tmp_path / "dithered.yaml").write_text(
        "plugins: [dithered.py]\n" + plain.replace(
            "  - {label: RLS, type: rls}", "  - {label: RLS, type: rls}\n"
                                           "  - {label: dithered, type: dithered}")
        .replace("claims:\n  - {better: EKF, worse: RLS}\n", ""))
    tables = {}
    for name, config, extra in (("one", "dithered", ["--jobs", "1"]),
                                ("two", "dithered", ["--jobs", "2"]),
                                ("seed", "dithered", ["--seed", "2"]),
                                ("plain", "plain", [])):
        out = tmp_path / name
        result = CliRunner().invoke(main, ["run", str(tmp_path / f"{config}.yaml"), "--out",
                                           str(out), *extra])
        assert result.exit_code == 0, result.output
        folder = next(p for p in out.iterdir() if p.is_dir())
        tables[name] = (folder / "rmse.csv").read_text()
    assert tables["one"] == tables["two"]
    assert tables["one"] != tables["seed"]
    rows = tables["one"].splitlines()
    dithered = [r for r in rows if ",dithered," in r]
    assert len(dithered) == 2 and dithered[0].split(",")[-3:] != dithered[1].split(",")[-3:]
    kept = [r for r in rows if ",dithered," not in r]
    assert kept == tables["plain"].splitlines()
