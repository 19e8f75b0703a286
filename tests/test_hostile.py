"""Bad input and faults (issue 9): one clear line and exit 2 before any work, never a hang,
an internal error or a silent NaN; a result folder is all old or all new."""

import copy
import functools
import io
import json
import math
import os
import pickle
import random
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml
from click.testing import CliRunner

from estim import store
from estim.cli.main import main
from estim.config.loading import parse_data, quick_data
from estim.config.overrides import apply_overrides
from estim.errors import ConfigError, ConfigErrors
from estim.store import folders

ROOT = Path(__file__).resolve().parents[1]
CONFIGS = {p.stem: yaml.safe_load(p.read_text())
           for p in [*sorted((ROOT / "configs").glob("*.yaml")),
                     *sorted((ROOT / "configs" / "studies").glob("*.yaml"))]}


def config(config_name: str, changes: dict) -> dict:
    """A shipped config with dotted-path ``changes`` (list items by index)."""
    return apply_overrides(CONFIGS[config_name], changes)


def validate_text(tmp_path: Path, text: str):
    path = tmp_path / "hostile.yaml"
    path.write_text(text)
    return path, CliRunner().invoke(main, ["validate", str(path)])


def assert_one_line_exit_2(result, path, key=None, expected=None):
    """Exit 2, one line per problem, each naming the file; one of them names ``key`` and
    says ``expected``."""
    assert result.exit_code == 2, result.output
    lines = result.output.strip().splitlines()
    assert lines and all(line.startswith("error: ") and str(path) in line for line in lines), \
        result.output
    assert "Traceback" not in result.output
    hits = [line for line in lines if (key is None or f": {key}: " in line)
            and (expected is None or expected in line)]
    assert hits, result.output


BOMB = "".join(f"l{i}: &l{i} [" + ", ".join([f"*l{i - 1}"] * 9 if i else ["lol"] * 9) + "]\n"
               for i in range(9))

HOSTILE = [
    # (config, changes, key path, expected words)
    ("mosfet_saturation", {"estimators.1.settings.order": 10**9}, "estimators[1].settings.order",
     "integer from 1 to 200"),
    ("mosfet_saturation", {"estimators.1.settings.order": math.inf},
     "estimators[1].settings.order", "integer"),
    ("mosfet_saturation", {"estimators.0.settings.substeps": 10**9},
     "estimators[0].settings.substeps", "integer from 1 to 1000"),
    ("mosfet_saturation", {"input.periods": 10**7}, "input.periods", "integer from 1 to 100000"),
    ("cco_distortion", {"excitation.samples": 10**8}, "excitation.samples", "integer from 8"),
    ("mosfet_distortion", {"excitation.samples_per_period": 10**7},
     "excitation.samples_per_period", "integer from 8 to 10000"),
    ("mosfet_saturation", {"input.frequencies_hz": list(range(1, 5001))},
     "input.frequencies_hz", "at most 100 entries"),
    ("mosfet_distortion", {"rows": [{"s_no": i, "amplitude_v": 0.01, "frequency_hz": 100}
                                    for i in range(1, 1001)]}, "rows", "at most 100 entries"),
    ("mosfet_saturation", {"simulation.solver": "scipy", "simulation.rtol": 1e-300},
     "simulation.rtol", "number >= 1e-12"),
    ("cco_distortion", {"rows.0.amplitude_v": 1e30}, "rows[0].amplitude_v", "<= 1000"),
    ("mosfet_saturation", {"estimators.0.label": "E" * 1_000_000}, "estimators[0].label",
     "at most 60 characters"),
    ("mosfet_saturation", {"estimators.1.settings.delta": math.inf},
     "estimators[1].settings.delta", "finite number"),
    ("mosfet_saturation", {"estimators.0.settings.divergence_bound": math.nan},
     "estimators[0].settings.divergence_bound", "finite number"),
    ("mosfet_saturation", {"estimators.0.settings.divergence_bound": -1},
     "estimators[0].settings.divergence_bound", "positive number"),
    ("mosfet_saturation", {"estimators.0.settings.x0": [math.nan] * 4},
     "estimators[0].settings.x0", "finite number"),
    ("mosfet_saturation", {"estimators.0.settings.Q": [[1, 2, 0, 0], [2, 1, 0, 0],
                                                       [0, 0, 1, 0], [0, 0, 0, 1]]},
     "estimators[0].settings.Q", "a positive semidefinite covariance"),
    ("mosfet_saturation", {"model.params.V_DD": math.inf}, "model.params.V_DD", "finite number"),
    ("mosfet_saturation", {"estimators.0.model_params": {"V_IN": math.nan}},
     "estimators[0].model_params.V_IN", "finite number"),
    ("mosfet_saturation", {"input.frequencies_hz": [1e-300]}, "input.frequencies_hz[0]",
     "number >= 0.001"),
    ("mosfet_saturation", {"tables.rmse": "4.1"}, "tables.rmse", "for a rmse table"),
    ("mosfet_saturation", {"tables.rmse": 4.1}, "tables.rmse", "a non-empty string"),
    ("mosfet_saturation", {"tables": {}}, "tables", "at least one of"),
    ("cco_distortion", {"rows.0.duration_s": 1e-300}, "rows[0].duration_s", "number >= 1e-09"),
    ("mosfet_saturation", {"tables.rmse": "2.4"}, "tables.rmse", "for a rmse table"),
    ("mosfet_distortion", {"tables.distortion": "3.1"}, "tables.distortion",
     "for a distortion table"),
    ("mosfet_saturation", {"noise.readings": ["sigma", "sigma"]}, "noise.readings[1]",
     "repeats 'sigma'"),
    ("mosfet_saturation", {"input.frequencies_hz": [100, 1000, 100]}, "input.frequencies_hz[2]",
     "repeats 100"),
    ("mosfet_saturation", {"model.params.V_IN": math.nan}, "model.params.V_IN", "finite number"),
    ("mosfet_saturation", {"model.params.V_DD": 1e308}, "model.params.V_DD", "times the default"),
    ("mosfet_saturation", {"estimators.0.settings.R": True}, "estimators[0].settings.R",
     "a finite number"),
    ("mosfet_saturation", {"figures.names": {"noisy": "same", "rmse": "same"}}, "figures.names",
     "share one file name"),
    ("mosfet_saturation", {"figures.extra_noisy": [{"noise_level": 0.1, "name": "fig_3_4"}]},
     "figures.extra_noisy[0].name", "already the file of figures.names.noiseless"),
    ("mosfet_saturation", {"check.tolerances.no_column": {"rtol": 0.1}},
     "check.tolerances.no_column", "no table of a estimation analysis has this column"),
    ("mosfet_saturation", {"check.tolerances.rmse": {"rtol": 1e308}},
     "check.tolerances.rmse.rtol", "number <= 1"),
    ("mosfet_saturation", {"name": "n" * 300}, "name", "at most 100 characters"),
    ("mosfet_saturation", {"figures.names": {"noisy": "f" * 300}}, "figures.names.noisy",
     "at most 100 characters"),
    ("mosfet_saturation", {"monte_carlo.runs": 10**6}, "", "raise it with --max-work"),
    ("mosfet_saturation", {"claims": [{"better": "EKF", "worse": "LMS"}]}, "claims[0].worse",
     "expected an estimator label"),
    ("mosfet_saturation", {"claims": [{"better": "EKF", "worse": "EKF"}]}, "claims[0].worse",
     "the same estimator as better"),
    ("kronecker_table_4_1", {"claims": [{"better": "EKF", "worse": "EKF"}]}, "claims[0].worse",
     "the same estimator as better"),
    ("mosfet_saturation", {"estimators.0.settings.noise_units": "volts"},
     "estimators[0].settings.noise_units", "['state', 'thesis']"),
    ("mosfet_saturation", {"check.tolerances.rmse": {"binomial": 4}},
     "check.tolerances.rmse.trials", "binomial needs"),
    ("mosfet_saturation", {"check.tolerances.rmse": {"se": 4, "se_column": "nope"}},
     "check.tolerances.rmse", "no column 'nope'"),
    ("mosfet_saturation", {"check.tolerances.rmse": {"se": 100}}, "check.tolerances.rmse.se",
     "number <= 10"),
    ("diffamp_em_printed_distortion", {"model.params.R_E": 1e-300}, "model.params",
     "linearisation at its operating point is not finite"),
    ("cco_distortion", {"rows.0.params": {"R_E": 1.0}}, "rows[0].params",
     "cco: no DC operating point found"),
    ("kronecker_table_4_2", {"estimators.1.settings.step": 2.5},
     "estimators[1].settings.step", "stability bound of normalised LMS"),
    ("kronecker_table_4_2", {"estimators.1.settings.measures": ["v_X"]},
     "estimators[1].settings.measures", "'v_X' is not a state of mosfet_ekv"),
    ("kronecker_table_4_2", {"estimators.3.settings.measures": ["v_G"]},
     "estimators[3].settings", "must include the output state 'v_D'"),
    ("kronecker_table_4_2", {"estimators.1.settings.wavelet": "morl"},
     "estimators[1].settings.wavelet", "not a discrete wavelet"),
    ("kronecker_table_4_2", {"estimators.0.settings.discretization": "rk4"},
     "estimators[0].settings.discretization", "'euler', 'exponential'"),
    ("kronecker_table_4_2", {"estimators.0.settings.order": 3}, "estimators[0].settings.order",
     "integer from 1 to 2"),
    ("kronecker_table_4_2", {"estimators.4.model": "nope"}, "estimators[4].model",
     "one of"),
    ("kronecker_table_4_2", {"noise.adc_range_v": [1.0, 0.0]}, "noise.adc_range_v",
     "low < high"),
    ("kronecker_table_4_2", {"noise.gamma": 0}, "noise.gamma", "positive number"),
    ("kronecker_table_4_2", {"geometry.columns.1": {"w_um": 2, "l_um": 2}},
     "geometry.columns[1]", "repeats"),
    ("kronecker_table_4_2", {"geometry.columns.0.w_um": -1}, "geometry.columns[0].w_um",
     "positive number"),
    ("kronecker_table_4_2", {"figures.names.0.w_um": 3}, "figures.names[0]",
     "no geometry column W = 3"),
    ("kronecker_table_4_2", {"tables.rmse": "3.1"}, "tables.rmse", "for a rmse table"),
    ("kronecker_table_4_2", {"claims": [{"better": "EKF", "worse": "RLS"}]}, "claims[0].worse",
     "expected an estimator label"),
    ("kronecker_table_4_1", {"truth.params": {"W_L": "big"}}, "truth.params.W_L",
     "a finite number"),
    ("kronecker_burden", {"stages": [1, 100]}, "stages[1]", "integer from 1 to 64"),
    ("kronecker_burden", {"model.name": "mosfet_ekv"}, "model.name",
     "no 'stages' parameter"),
    ("kronecker_burden", {"wavelet.step": 3}, "wavelet.step", "stability bound"),
    ("kronecker_burden", {"ekf.order": 3}, "ekf.order", "integer from 1 to 2"),
    ("kronecker_burden", {"tables.burden_ekf": "9.9"}, "tables.burden_ekf", "9.9"),
    ("dipole_literal", {"zones.0.r": [0.2, 0.1]}, "zones[0].r", "low < high"),
    ("dipole_literal", {"zones.1.name": "near"}, "zones[1].name", "repeats 'near'"),
    ("dipole_literal", {"kf.Q": [1e-4, 1e-3]}, "kf.Q", "4 diagonal entries"),
    ("dipole_literal", {"kf.R": 0}, "kf.R", "positive number"),
    ("dipole_literal", {"rls.lambda0": 1.5}, "rls.lambda0", "number <= 1"),
    ("dipole_literal", {"variant": "field"}, "variant", "'literal'"),
    ("dipole_literal", {"zones.0.theta_deg": [0, 90]}, "zones[0].theta_deg[0]", ">= 1"),
    ("dipole_literal", {"time.samples_per_period": 4}, "time.samples_per_period",
     "integer from 8"),
    ("dipole_field", {"grid.n": 31}, "grid.n", "even number"),
    ("dipole_field", {"grid.courant": 0.6}, "grid.courant", "number <= 0.577"),
    ("dipole_field", {"zones.1.r": [1.2, 2.5]}, "zones[1].r", "reaches the box's faces"),
    ("dipole_field", {"sensors.fraction": 0.9}, "sensors.fraction", "only"),
    ("dipole_field", {"scenarios.1.name": "true source"}, "scenarios[1].name", "repeats"),
    ("dipole_field", {"scenarios.0.nominal_amplitude": [1.0]},
     "scenarios[0].nominal_amplitude", "[magnitude, phase in degrees]"),
    ("dipole_field", {"filter.members": 2}, "filter.members", "integer from 3"),
    ("dipole_field", {"grid.boundary": "pml"}, "grid.boundary", "'dirichlet', 'mur'"),
    ("dipole_field", {"filter.block": 5}, "filter.block", "divisor of grid.n"),
    ("dipole_field", {"filter.field_error": -0.1}, "filter.field_error", "number >= 0"),
    ("dipole_field", {"filter.field_error_profile": "shell"}, "filter.field_error_profile",
     "'truncation', 'uniform'"),
    ("dipole_field", {"filter.field_error_length": 0}, "filter.field_error_length",
     "positive number"),
    ("dipole_field", {"filter.localisation": 0}, "filter.localisation", "positive number"),
    ("dipole_field", {"filter.amplitude_localisation": "far"},
     "filter.amplitude_localisation", "number"),
    ("dipole_field", {"filter.representation_error": -1}, "filter.representation_error",
     "number >= 0"),
    ("dipole_field", {"source_only.representation_error": "x"},
     "source_only.representation_error", "number"),
    ("dipole_field", {"filter.model_error": 0.02}, "filter.model_error", "unknown key"),
    ("field_grid", {"study.values": [16, 30]}, "study.values[1]", "grid.n = 30: filter.block"),
    ("field_grid", {"study.setting": "grid.length"}, "study.setting", "'filter.members'"),
    ("field_members", {"study.values": [20.5]}, "study.values[0]", "whole number"),
    ("fir_differentiator", {"bands": [1.5]}, "bands[0]", "number <= 0.999"),
    ("fir_differentiator", {"thresholds_db": [10]}, "thresholds_db[0]", "number <= -1"),
    ("fir_differentiator", {"max_taps": 5000}, "max_taps", "integer from 4 to 1024"),
    ("fir_differentiator", {"tables.orders": "3.1"}, "tables.orders", "for a orders table"),
    ("kalman_differentiator", {"cases.0.r": 0}, "cases[0].r", "positive number"),
    ("kalman_differentiator", {"cases.0.dt": 100}, "cases[0].dt", "number <= 10"),
    ("kalman_differentiator", {"monte_carlo.runs": 0}, "monte_carlo.runs", "integer from 1"),
    ("passive_network", {"readings.0.coupling": "both"}, "readings[0].coupling",
     "'flipped', 'printed'"),
    ("passive_network", {"readings.1.name": "printed, x fed, from T"}, "readings[1].name",
     "repeats"),
    ("passive_network", {"readings.0.feed": "y"}, "readings[0].feed", "'x', 'z'"),
    ("passive_network", {"sample_time": 0}, "sample_time", "positive number"),
    ("passive_network", {"figures.0.A": 7}, "figures[0].A", "the A of a signal"),
    ("image_kalman", {"images": ["camera", "eagle"]}, "images[1]", "'astronaut', 'brick'"),
    ("image_kalman", {"images": ["camera", "camera"]}, "images[1]", "repeats"),
    ("image_kalman", {"nshp.order": 4}, "nshp.order", "integer from 1 to 3"),
    ("image_kalman", {"adaptive.v0": 0}, "adaptive.v0", "positive number"),
    ("image_kalman", {"adaptive.gradient": "exact"}, "adaptive.gradient", "'approximate'"),
    ("image_kalman", {"figures.image": "coins"}, "figures.image", "expected one of the images"),
    ("image_kalman", {"figures.row": 600}, "figures.row", "has 512 rows"),
    ("image_kalman", {"crop": 600}, "crop", "is 512 x 512 pixels"),
    ("image_kalman", {"crop": 8}, "crop", "integer from 16 to 4096"),
    ("image_kalman", {"crop": 64}, "figures.row", "has 64 rows"),
    ("image_kalman", {"crop": 300, "figures.pixels": 400}, "figures.pixels", "has 300 columns"),
    ("image_kalman", {"monte_carlo.runs": 0}, "monte_carlo.runs", "integer from 1"),
    ("image_kalman", {"strip.width": 0}, "strip.width", "integer from 1 to 64"),
    ("image_kalman", {"strip.covariance": "mle"}, "strip.covariance", "'biased', 'unbiased'"),
    ("image_kalman", {"strip.eigenvalue_floor": 0}, "strip.eigenvalue_floor", "positive"),
    ("passive_network", {"figures.1.errors": "fig_4"}, "figures[1].errors", "repeats"),
    ("passive_network", {"figures.1.signal": "../x"}, "figures[1].signal", None),
    ("kronecker_table_4_2", {"noise.adc_bits": 64}, "noise.adc_bits", "integer from 1 to 32"),
    ("kronecker_table_4_2", {"geometry.reference_area_um2": -4}, "geometry.reference_area_um2",
     "positive number"),
    ("kronecker_table_4_2", {"input.samples_per_period": 2}, "input.samples_per_period",
     "integer from 4"),
    ("kronecker_table_4_2", {"estimators.0.settings.jacobian": "none"},
     "estimators[0].settings.jacobian", "'full', 'printed'"),
    ("kronecker_table_4_2", {"estimators.1.settings.solver": "sgd"},
     "estimators[1].settings.solver", "'least_squares', 'lms'"),
    ("kronecker_table_4_2", {"estimators.1.settings.epochs": 0},
     "estimators[1].settings.epochs", "integer from 1"),
    ("kronecker_table_4_2", {"estimators.1.settings.band_factor": -1},
     "estimators[1].settings.band_factor", "positive number"),
    ("kronecker_burden", {"timing.batch_runs": 1}, "timing.batch_runs", "integer from 2"),
    ("dipole_literal", {"source.frequency": 0}, "source.frequency", "positive number"),
    ("dipole_literal", {"zones.0.points_r": 2}, "zones[0].points_r", "integer from 3"),
    ("dipole_field", {"filter.inflation": 0.5}, "filter.inflation", "number >= 1"),
    ("dipole_field", {"sensors.seed": -1}, "sensors.seed", "integer"),
    ("dipole_field", {"sensors.seed": "five"}, "sensors.seed", "integer"),
    ("dipole_field", {"sensors.measurement_sigma": 0}, "sensors.measurement_sigma",
     "a number >= 1e-12"),
    ("dipole_field", {"time.spinup_periods": 0}, "time.spinup_periods", "integer from 1"),
    ("mosfet_input_derivative", {"estimators.1.input_derivative": "spline"},
     "estimators[1].input_derivative", "'analytic', 'difference', 'kalman'"),
    ("mosfet_input_derivative", {"estimators.1.derivative_bandwidth": 0},
     "estimators[1].derivative_bandwidth", "number"),
    ("mosfet_input_derivative", {"noise.input_sensor_sigma": -0.1},
     "noise.input_sensor_sigma", "number >= 0"),
    ("mosfet_input_derivative", {"noise.filters_see": "nominal"}, "noise.input_sensor_sigma",
     "filters_see: noisy"),
    ("diffamp_ekf", {"estimators.0.input_derivative": "kalman"},
     "estimators[0].input_derivative", "not the derivative of its source"),
    ("mosfet_input_derivative", {"tables.rmse": "3.7"}, "tables.rmse", "'3.1', '3.2', '3.5'"),
]


@pytest.mark.parametrize("name, changes, key, expected", HOSTILE,
                         ids=[f"{h[0]}:{h[2] or 'work'}" for h in HOSTILE])
def test_hostile_config_is_one_line_and_exit_2(tmp_path, name, changes, key, expected):
    path, result = validate_text(tmp_path, yaml.safe_dump(config(name, changes)))
    assert_one_line_exit_2(result, path, key or None, expected)


DIFFAMP_NETLIST = str(ROOT / "circuits" / "diffamp_em.cir")
GOOD_BLOCK = {"netlist": DIFFAMP_NETLIST, "input": ["VB1", "VB2"], "output": "v(c1,c2)"}


@pytest.mark.parametrize("block, key, expected", [
    ({**GOOD_BLOCK, "netlist": "nope.cir"}, "model.netlist", "no file 'nope.cir'"),
    ({**GOOD_BLOCK, "netlist": 3}, "model.netlist", "expected a file name"),
    ({**GOOD_BLOCK, "input": 5}, "model.input", "the name of the voltage source"),
    ({**GOOD_BLOCK, "output": 7}, "model.output", "v(node)"),
    ({**GOOD_BLOCK, "output": "v(zz)"}, "model.netlist", "node zz is not a state node"),
    ({**GOOD_BLOCK, "input": ["VX"]}, "model.netlist",
     "input 'vx' is not a voltage or current source"),
    ({**GOOD_BLOCK, "name": "diffamp_em"}, "model.name", "either a registered model"),
    ({**GOOD_BLOCK, "netlist": "BAD"}, "model.netlist", "bad.cir:3: unknown element 'z1'"),
    ({**GOOD_BLOCK, "input": ["VB1", "VB1"]}, "model.netlist", "input 'vb1' named more than"),
    ({**GOOD_BLOCK, "params": {"zz": 1}}, "model.params.zz", "its .param names"),
    ({**GOOD_BLOCK, "params": {"rl": -5}}, "model.params",
     "diffamp_em.cir:12: rl: the value must be positive"),
    ({**GOOD_BLOCK, "params": {"cl": "x"}}, "model.params.cl", ""),
    ({**GOOD_BLOCK, "hold": "middle"}, "model.hold", "mean, start or end"),
    ({"name": "diffamp_em", "hold": "start"}, "model.hold", "only with model.netlist"),
    ({"name": "diffamp_em", "output": "v(x)"}, "model.output", "only with model.netlist"),
    ({"name": "diffamp_em", "thesis_states": ["v(e)"]}, "model.thesis_states",
     "only with model.netlist"),
    ({**GOOD_BLOCK, "thesis_states": "v(e)"}, "model.thesis_states", "a list of v(node)"),
    ({**GOOD_BLOCK, "thesis_states": ["v(e)"]}, "model.thesis_states",
     "1 given, the netlist has 4 states (v(c1), v(c2), v(e), v(m))"),
    ({**GOOD_BLOCK, "thesis_states": ["v(e)", "v(m,c2)", "v(c1)", "v(zz)"]},
     "model.thesis_states", "node zz is not a state node"),
    ({**GOOD_BLOCK, "thesis_states": ["v(e)", "v(m,c2)", "v(c1)", "v(c1,e)"]},
     "model.thesis_states", "one is a combination of the others"),
], ids=lambda v: v if isinstance(v, str) else None)
def test_a_bad_netlist_model_block_is_one_line_and_exit_2(tmp_path, block, key, expected):
    if block.get("netlist") == "BAD":
        (tmp_path / "bad.cir").write_text("title\nV1 a 0 DC 1\nZ1 a 0 1k\n")
        block = {**block, "netlist": str(tmp_path / "bad.cir")}
    spec = config("diffamp_em_distortion", {})
    spec["model"] = block
    path, result = validate_text(tmp_path, yaml.safe_dump(spec))
    assert_one_line_exit_2(result, path, key, expected)


def test_a_netlist_model_block_validates(tmp_path):
    spec = config("diffamp_em_distortion", {})
    spec["model"] = GOOD_BLOCK
    path, result = validate_text(tmp_path, yaml.safe_dump(spec))
    assert result.exit_code == 0, result.output


@pytest.mark.parametrize("text, expected", [
    (BOMB, "YAML aliases"),
    ("name: a\ntitle: t\nname: b\n", "line 3: duplicate key 'name'"),
    ("input:\n  amplitude_v: 0.01\n  amplitude_v: 0.02\n", "duplicate key 'amplitude_v'"),
    ("[" * 5000 + "]" * 5000, "nested deeper than 32 levels"),
    ("1: a\n", "is not a string"),
    ("? [a, b]\n: 1\n", "a key that is not a plain value"),
    ("\x00\x01", "not valid YAML"),
    ("noise: &n {input_levels: [0.1]}\nx:\n  <<: *n\n  a: 1\n  a: 2\n", "duplicate key 'a'"),
])
def test_hostile_yaml_is_one_line_and_exit_2(tmp_path, text, expected):
    path, result = validate_text(tmp_path, text)
    assert_one_line_exit_2(result, path, expected=expected)


def test_libyaml_reads_every_shipped_config_as_the_bounded_reader_does():
    """The fast reader (libyaml) and the bounded one give the same mapping; a text with an
    alias, a deep block or a bracket hidden in quotes goes to the bounded one."""
    from estim.config import yaml_reader

    texts = [p.read_text() for p in sorted((ROOT / "configs").rglob("*.yaml"))]
    plain = [t for t in texts if yaml_reader._plain(t)]
    assert len(plain) >= len(texts) // 2
    for text_ in plain:
        assert (yaml.load(text_, Loader=yaml_reader.FastConfigLoader)  # noqa: S506
                == yaml.load(text_, Loader=yaml_reader.ConfigLoader))  # noqa: S506
    deep_block = "".join(" " * i + f"k{i}:\n" for i in range(40)) + " " * 40 + "v: 1\n"
    hidden = "x: " + "[" * 40 + '"' + "]" * 39 + '"' + "]" * 40 + "\n"
    for text_ in (deep_block, hidden, BOMB, "x: [1,\n 2]\n"):
        assert not yaml_reader._plain(text_)


def test_device_files_and_fifos_are_refused_before_reading(tmp_path):
    fifo = tmp_path / "pipe.yaml"
    os.mkfifo(fifo)
    for path in (Path("/dev/zero"), fifo, tmp_path):
        result = CliRunner().invoke(main, ["validate", str(path)])
        assert_one_line_exit_2(result, path, expected="not a regular file")
    big = tmp_path / "big.yaml"
    big.write_text("title: " + "x" * (2 << 20) + "\n")
    assert_one_line_exit_2(CliRunner().invoke(main, ["validate", str(big)]), big,
                           expected="larger than 1024 KiB")


# ----- fuzzing: a few hundred seeded mutations of the shipped configs ------------------------

FUZZ_VALUES = [math.inf, -math.inf, math.nan, 0, -1, 1e308, -1e308, 1e-300, True, False, None,
               "", "x" * 300, [], {}, [1] * 150, 10**9, "4.1", [[[[[]]]]], 1e30, 0.5, "sigma"]


def _paths(node, prefix=()):
    yield prefix
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _paths(v, prefix + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _paths(v, prefix + (i,))


def mutate(spec: dict, rng: random.Random) -> tuple[dict, str]:
    """One random change: a hostile value, a deleted key, a repeated item or an unknown key."""
    spec = copy.deepcopy(spec)
    path = rng.choice([p for p in _paths(spec) if p])
    parent = spec
    for key in path[:-1]:
        parent = parent[key]
    last, op = path[-1], rng.random()
    if op < 0.7:
        value = rng.choice(FUZZ_VALUES)
        parent[last] = copy.deepcopy(value)
        return spec, f"{path} = {str(value)[:20]}"
    if op < 0.8 and isinstance(parent, dict):
        del parent[last]
        return spec, f"del {path}"
    if op < 0.9 and isinstance(parent, list):
        parent.append(copy.deepcopy(parent[last]))
        return spec, f"repeat {path}"
    target = parent[last] if isinstance(parent[last], dict) else None
    if target is not None:
        target["zz_unknown"] = 1
        return spec, f"unknown key under {path}"
    parent[last] = {"nested": parent[last]}
    return spec, f"wrap {path}"


class _Hang(Exception):
    pass


def _alarm(*_):
    raise _Hang


@functools.cache
def fuzz(n: int, seed: int) -> tuple[list[str], list[tuple[str, dict, str]]]:
    """Problems (hang, internal error, multi-line message) and the accepted mutants."""
    rng = random.Random(seed)
    problems, accepted = [], []
    previous = signal.signal(signal.SIGALRM, _alarm)
    try:
        for _ in range(n):
            name = rng.choice(sorted(CONFIGS))
            spec, what = mutate(CONFIGS[name], rng)
            signal.alarm(5)
            try:
                parse_data(spec, "fuzz.yaml", "fuzz")
                accepted.append((name, spec, what))
            except ConfigError as exc:
                # one line per problem (several problems of one file: one line each), every
                # line naming the file
                lines = str(exc).split("\n")
                if len(lines) > 1 and not isinstance(exc, ConfigErrors) or \
                        not all(line.startswith("fuzz.yaml: ") for line in lines):
                    problems.append(f"{name} {what}: message {str(exc)[:100]!r}")
            except _Hang:
                problems.append(f"{name} {what}: hangs")
            except Exception as exc:  # noqa: BLE001 - what the fuzz test looks for
                problems.append(f"{name} {what}: {type(exc).__name__}: {exc}"[:200])
            finally:
                signal.alarm(0)
    finally:
        signal.signal(signal.SIGALRM, previous)
    return problems, accepted


def test_fuzzed_configs_end_in_a_config_error_or_validate():
    problems, accepted = fuzz(300, seed=9)
    assert not problems, "\n".join(problems)
    assert 0 < len(accepted) < 150


@pytest.mark.slow
def test_accepted_mutants_run_or_fail_in_one_line_without_silent_nan(tmp_path):
    _, accepted = fuzz(300, seed=9)
    rng = random.Random(3)
    for i, (name, spec, what) in enumerate(rng.sample(accepted, 6)):
        spec = quick_data(parse_data(copy.deepcopy(spec), "t.yaml", "t", plan=False))
        spec["name"] = f"m{i}"
        path = tmp_path / f"m{i}.yaml"
        path.write_text(yaml.safe_dump(spec))
        result = CliRunner().invoke(main, ["run", str(path), "--out", str(tmp_path / "out"),
                                           "--quiet"])
        assert result.exit_code in (0, 2, 3), f"{name} {what}: {result.output}"
        if result.exit_code:
            assert len(result.output.strip().splitlines()) == 1, f"{name} {what}"
            continue
        folder = tmp_path / "out" / f"m{i}"
        for table in folder.glob("*.csv"):
            df = pd.read_csv(table)
            if "rmse" in df:      # a NaN RMSE only where every run diverged
                silent = df["rmse"].isna() & (df["runs"] > 0)
                assert not silent.any(), f"{name} {what}: {table.name}"
            if "percent_distortion" in df:
                assert df["percent_distortion"].notna().all(), f"{name} {what}"


# ----- faults: a result folder is all old or all new -----------------------------------------

def tiny_spec(name="tiny", runs=3, periods=2) -> dict:
    spec = quick_data(parse_data(copy.deepcopy(CONFIGS["mosfet_saturation"]), "t.yaml", "t",
                                 plan=False))
    spec["name"] = name
    spec["monte_carlo"]["runs"] = runs
    spec["input"]["periods"] = periods
    return spec


def folder_is_whole(folder: Path) -> str:
    """'old' or 'new' by the manifest's seed, after checking every file against it."""
    import json

    manifest = json.loads((folder / "manifest.json").read_text())
    files = {str(p.relative_to(folder)) for p in folder.rglob("*") if p.is_file()}
    assert files - {"manifest.json", "run.json"} == set(manifest["files"]), files
    for name, digest in manifest["files"].items():
        assert store.sha256(folder / name) == digest, name
    return {1: "old", 2: "new"}[manifest["seed"]]


def test_a_failed_write_leaves_the_old_folder(tmp_path, monkeypatch):
    path = tmp_path / "tiny.yaml"
    path.write_text(yaml.safe_dump(tiny_spec()))
    out = tmp_path / "out"
    runner = CliRunner()
    assert runner.invoke(main, ["run", str(path), "--out", str(out), "--quiet",
                                "--seed", "1"]).exit_code == 0
    calls = []

    def full_disk(fig, target):
        calls.append(target)
        if len(calls) == 2:
            raise OSError(28, "No space left on device", str(target))
        return real(fig, target)

    real = store.write_figure
    monkeypatch.setattr(store, "write_figure", full_disk)
    result = runner.invoke(main, ["run", str(path), "--out", str(out), "--quiet",
                                  "--seed", "2"])
    assert result.exit_code == 3
    assert result.output.strip().splitlines() == [
        f"error: No space left on device ({calls[1]})"]
    assert folder_is_whole(out / "tiny") == "old"
    # no half folder; the finished cells wait (hidden) for the re-run, which takes them
    left = sorted(p.name for p in out.iterdir())
    assert left[1:] == [".tiny.lock", "tiny"] and left[0].startswith(".tiny.cells-")
    monkeypatch.setattr(store, "write_figure", real)
    again = runner.invoke(main, ["run", str(path), "--out", str(out), "--seed", "2"])
    assert again.exit_code == 0 and "resumed with" in again.output
    assert sorted(p.name for p in out.iterdir()) == [".tiny.lock", "tiny"]


def test_not_enough_space_is_found_before_any_work(tmp_path, monkeypatch):
    path = tmp_path / "tiny.yaml"
    path.write_text(yaml.safe_dump(tiny_spec()))
    monkeypatch.setattr(folders.shutil, "disk_usage", lambda p: type("U", (), {"free": 1024})())
    result = CliRunner().invoke(main, ["run", str(path), "--out", str(tmp_path / "out")])
    assert result.exit_code == 2 and "not enough free space" in result.output
    assert "work units" not in result.output


def test_read_only_folder_is_found_before_any_work(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    locked = subprocess.run(["chattr", "+i", str(out)], capture_output=True).returncode == 0
    if not locked:
        if os.geteuid() == 0:
            pytest.skip("no way to make a folder read-only for root here (chattr failed)")
        out.chmod(0o555)
    try:
        path = tmp_path / "tiny.yaml"
        path.write_text(yaml.safe_dump(tiny_spec()))
        result = CliRunner().invoke(main, ["run", str(path), "--out", str(out)])
        assert result.exit_code == 2, result.output
        assert f"cannot write to {out}" in result.output and "work units" not in result.output
    finally:
        if locked:
            subprocess.run(["chattr", "-i", str(out)], check=True)
        out.chmod(0o755)


def interruptible() -> None:
    """A child's SIGINT back at its default. A job a non-interactive shell starts in the
    background ignores SIGINT, its children inherit that, and Python then keeps ignoring it:
    a Ctrl-C test run so would see the command finish (exit 0) instead of stop."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def estim(*args, cwd):
    return subprocess.Popen([sys.executable, "-m", "estim.cli.main", *args], cwd=cwd,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=interruptible)


def started(run) -> str:
    """The next line of ``run``'s standard error but the notice a run with no compiled
    kernel cached yet prints first."""
    line = run.stderr.readline()
    while line.startswith("first run: "):
        line = run.stderr.readline()
    return line


@pytest.mark.slow
def test_killed_run_leaves_the_folder_all_old_or_all_new(tmp_path):
    path = tmp_path / "tiny.yaml"
    path.write_text(yaml.safe_dump(tiny_spec(runs=8, periods=4)))
    out = tmp_path / "out"
    args = ["run", str(path), "--out", str(out), "--quiet"]
    first = estim(*args, "--seed", "1", cwd=tmp_path)
    start = time.perf_counter()
    assert first.wait(timeout=120) == 0, first.stderr.read()
    duration = time.perf_counter() - start
    for fraction in (0.9, 1.02):
        run = estim(*args, "--seed", "2", cwd=tmp_path)
        time.sleep(duration * fraction)
        run.send_signal(signal.SIGKILL)
        run.wait(timeout=60)
        assert folder_is_whole(out / "tiny") in ("old", "new")
        # whatever was left, the next run starts clean and restores the unit
        done = estim(*args, "--seed", "1", cwd=tmp_path)
        assert done.wait(timeout=120) == 0, done.stderr.read()
        assert folder_is_whole(out / "tiny") == "old"
        assert not list(out.glob(".tiny.partial-*")) and not list(out.glob(".tiny.old-*"))


@pytest.mark.slow
def test_concurrent_run_into_one_folder_is_refused(tmp_path):
    path = tmp_path / "tiny.yaml"
    path.write_text(yaml.safe_dump(tiny_spec(runs=10, periods=4)))
    out = tmp_path / "out"
    first = estim("run", str(path), "--out", str(out), "--quiet", cwd=tmp_path)
    deadline = time.time() + 30
    while not list(out.glob(".tiny.partial-*")) and time.time() < deadline:
        time.sleep(0.05)
    second = CliRunner().invoke(main, ["run", str(path), "--out", str(out), "--quiet"])
    assert second.exit_code == 2 and "another estim run is writing" in second.output
    assert first.wait(timeout=120) == 0
    assert CliRunner().invoke(main, ["run", str(path), "--out", str(out),
                                     "--quiet"]).exit_code == 0


def test_ctrl_c_is_one_line_and_exit_130(tmp_path):
    path = tmp_path / "tiny.yaml"
    spec = tiny_spec(runs=200, periods=40)
    spec["input"]["frequencies_hz"] = [100, 1000, 10000]
    path.write_text(yaml.safe_dump(spec))
    run = estim("run", str(path), "--out", str(tmp_path / "out"), "--jobs", "2", cwd=tmp_path)
    assert "work units" in started(run)       # the computation has started
    time.sleep(0.5)
    run.send_signal(signal.SIGINT)
    assert run.wait(timeout=60) == 130
    rest = run.stderr.read()
    assert rest.strip().splitlines() == ["error: interrupted"], rest
    assert not (tmp_path / "out" / "tiny").exists()


# ----- corrupt stored files are named -----------------------------------------------------------

@pytest.fixture
def stored(tmp_path):
    path = tmp_path / "tiny.yaml"
    path.write_text(yaml.safe_dump(tiny_spec()))
    out = tmp_path / "res"
    assert CliRunner().invoke(main, ["run", str(path), "--out", str(out), "--quiet"]).exit_code == 0
    return path, out


@pytest.mark.parametrize("damage, expected", [
    ("", "empty, not a table"),
    ("a,b\n1,2,3\n", "line 2 has 3 fields"),
    ("table_id,s_no\n3.2,1\n", "no column"),
])
def test_check_names_a_corrupt_stored_table(stored, damage, expected, rehash):
    path, out = stored
    (out / "tiny" / "rmse.csv").write_text(damage)
    rehash(out / "tiny")                # a file its manifest agrees with: the parser meets it
    result = CliRunner().invoke(main, ["check", str(path), "--results", str(out)])
    assert result.exit_code == 1
    assert f"{out / 'tiny' / 'rmse.csv'}" in result.output and expected in result.output


def test_check_reports_missing_manifest_and_figure(stored):
    path, out = stored
    (out / "tiny" / "figures" / "fig_3_5.png").write_bytes(b"not the figure")
    result = CliRunner().invoke(main, ["check", str(path), "--results", str(out)])
    assert result.exit_code == 1 and "figures/fig_3_5.png: not the file its manifest" \
        in result.output
    (out / "tiny" / "figures" / "fig_3_4.png").unlink()
    result = CliRunner().invoke(main, ["check", str(path), "--results", str(out)])
    assert result.exit_code == 1 and "figures/fig_3_4.png: missing" in result.output
    (out / "tiny" / "manifest.json").write_text("{not json")
    result = CliRunner().invoke(main, ["check", str(path), "--results", str(out)])
    assert result.exit_code == 1 and "manifest.json: not a readable estim manifest" in result.output


def test_table_names_a_file_with_text_in_a_number_column(stored, rehash):
    _, out = stored
    target = out / "tiny" / "rmse.csv"
    lines = target.read_text().splitlines()
    header = lines[0].split(",")
    cells = lines[1].split(",")
    cells[header.index("rmse")] = "garbage"
    target.write_text("\n".join([lines[0], ",".join(cells), *lines[2:]]) + "\n")
    rehash(out / "tiny")
    result = CliRunner().invoke(main, ["table", "rmse", "--results", str(out)])
    assert result.exit_code == 2
    assert f"{target}: line 2, column rmse: 'garbage' is not a number" in result.output
    target.write_text(lines[0] + "\n1,2\n")
    rehash(out / "tiny")
    result = CliRunner().invoke(main, ["table", "rmse", "--results", str(out)])
    assert result.exit_code == 2 and "line 2 has 2 fields" in result.output


def test_max_work_raises_the_work_limit(tmp_path):
    path, result = validate_text(tmp_path, yaml.safe_dump(
        config("mosfet_saturation", {"monte_carlo.runs": 10**6})))
    assert_one_line_exit_2(result, path, expected="raise it with --max-work")
    raised = CliRunner().invoke(main, ["validate", str(path), "--max-work", str(10**12)])
    assert raised.exit_code == 0, raised.output
    absurd = tmp_path / "absurd.yaml"
    absurd.write_text(yaml.safe_dump(config("kalman_differentiator", {"cases.0.dt": 1e-300})))
    quick = CliRunner().invoke(main, ["run", str(absurd), "--quick", "--max-work", "5"])
    assert quick.exit_code == 2 and "too much for any run" in quick.output, quick.output
    assert "raise it with --max-work" not in quick.output     # no --max-work lifts that bound


# ----- issue 28: damaged stored results, exit codes, bounded messages ---------------------------

def _damage(target: Path, kind: str) -> None:
    """Put something other than a regular file (or a file past its bounds) at ``target``."""
    target.unlink()
    if kind == "fifo":
        os.mkfifo(target)
    elif kind == "directory":
        target.mkdir()
    elif kind == "symlink loop":
        target.symlink_to(target)
    elif kind == "device":
        target.symlink_to("/dev/zero")
    elif kind == "huge":
        with target.open("w") as fh:
            fh.write("a,b\n")
            fh.write("1,2\n" * (store.MAX_TABLE_BYTES // 4 + 1))


def _command(*args: str, timeout: float = 60) -> subprocess.CompletedProcess:
    """``estim ARGS`` as a process (a hang is a failure, not a stuck test)."""
    return subprocess.run([sys.executable, "-m", "estim.cli.main", *args], capture_output=True,
                          text=True, timeout=timeout, cwd=ROOT)


@pytest.mark.parametrize("kind", ["fifo", "directory", "symlink loop", "device", "huge"])
@pytest.mark.parametrize("command", ["table", "report"])
def test_a_damaged_stored_table_is_named_and_exit_2(stored, kind, command):
    _, out = stored
    target = out / "tiny" / "rmse.csv"
    _damage(target, kind)
    args = (["table", "rmse", "--results", str(out)] if command == "table" else
            ["report", "--results", str(out), "--out", str(out / "page.html")])
    result = _command(*args)
    assert result.returncode == 2, result.stderr
    assert str(target) in result.stderr and "Traceback" not in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1, result.stderr
    assert not (out / "page.html").exists()


@pytest.mark.parametrize("kind", ["fifo", "huge", "deep", "directory"])
def test_a_damaged_stored_manifest_is_named_and_exit_2(stored, kind):
    _, out = stored
    target = out / "tiny" / "manifest.json"
    if kind == "deep":
        target.write_text("[" * 100_000 + "]" * 100_000)
    elif kind == "huge":
        target.write_text('{"config": {}, "pad": "' + "x" * (store.MAX_MANIFEST_BYTES + 1) + '"}')
    else:
        _damage(target, kind)
    for args in (["table", "rmse", "--results", str(out)], ["summary", "--results", str(out)],
                 ["report", "--results", str(out), "--out", str(out / "page.html")]):
        result = _command(*args)
        assert result.returncode == 2, result.stderr
        assert str(target) in result.stderr and "Traceback" not in result.stderr


def test_a_header_only_table_or_an_unknown_analysis_is_not_left_out_silently(stored, rehash):
    _, out = stored
    target = out / "tiny" / "rmse.csv"
    target.write_text(target.read_text().splitlines()[0] + "\n")
    rehash(out / "tiny")
    for args in (["table", "rmse", "--results", str(out)],
                 ["report", "--results", str(out), "--out", str(out / "page.html")]):
        result = _command(*args)
        assert result.returncode == 2 and "a header and no rows" in result.stderr, result.stderr
    manifest = out / "tiny" / "manifest.json"
    data = json.loads(manifest.read_text())
    data["config"]["analysis"] = "no_such_analysis"
    manifest.write_text(json.dumps(data))
    rehash(out / "tiny")
    result = _command("report", "--results", str(out), "--out", str(out / "page.html"))
    assert result.returncode == 2 and "unknown analysis 'no_such_analysis'" in result.stderr


def test_report_checks_its_target_before_building_the_page(stored):
    _, out = stored
    result = _command("report", "--results", str(out), "--out", "/proc/estim-report.html")
    assert result.returncode == 2 and "cannot write to /proc" in result.stderr, result.stderr


@pytest.mark.parametrize("command", ["run", "reproduce", "report", "merge"])
def test_an_empty_out_is_refused(tmp_path, command):
    args = {"run": ["run", "configs/fir_differentiator.yaml"],
            "reproduce": ["reproduce"], "report": ["report"],
            "merge": ["merge", "configs/fir_differentiator.yaml"]}[command]
    result = CliRunner().invoke(main, [*args, "--out", ""])
    assert result.exit_code == 2 and "expected a path, got an empty string" in result.output


def test_settle_at_or_after_the_record_is_a_config_error(tmp_path):
    for settle in (5.0, 7.5):
        path, result = validate_text(tmp_path, yaml.safe_dump(config(
            "kalman_differentiator", {"settle_s": settle, "record_s": 5.0})))
        assert_one_line_exit_2(result, path, "settle_s", "expected less than record_s")


def test_a_kf_sized_for_another_model_is_refused_at_validate(tmp_path):
    spec = config("mosfet_saturation", {})
    spec["estimators"] = [{"label": "EKF", "type": "kf", "settings": {
        "A": 1.0, "B": 0.0, "C": 1.0, "Q": 1.0, "R": 1.0, "P0": 1.0}}]
    path, result = validate_text(tmp_path, yaml.safe_dump(spec))
    assert_one_line_exit_2(result, path, "estimators[0].settings.A",
                           "1 rows, but the model mosfet_ekv has 4 states")


@pytest.mark.slow
def test_merge_recomputes_a_damaged_cell_and_names_a_directory_in_its_place(tmp_path):
    path = tmp_path / "tiny.yaml"
    path.write_text(yaml.safe_dump(tiny_spec()))
    runner = CliRunner()
    shard = tmp_path / "s1"
    done = runner.invoke(main, ["run", str(path), "--out", str(shard), "--shard", "1/2",
                                "--quiet"])
    assert done.exit_code == 0, done.output
    cells = sorted(shard.glob(".tiny.cells-*/cell-*.npz"))
    assert cells
    cells[0].write_bytes(pickle.dumps("not a cell"))            # the wrong type
    merged = runner.invoke(main, ["merge", str(path), "--from", str(shard), "--out",
                                  str(tmp_path / "m"), "--quiet"])
    assert merged.exit_code == 0, merged.output
    reference = runner.invoke(main, ["run", str(path), "--out", str(tmp_path / "r"),
                                     "--quiet"])
    assert reference.exit_code == 0
    assert ((tmp_path / "m" / "tiny" / "rmse.csv").read_bytes()
            == (tmp_path / "r" / "tiny" / "rmse.csv").read_bytes())
    cells[0].unlink()
    cells[0].mkdir()                                             # a directory in its place
    again = runner.invoke(main, ["merge", str(path), "--from", str(shard), "--out",
                                 str(shard), "--quiet"])
    assert again.exit_code == 2, again.output
    assert str(cells[0]) in again.output and "not a regular file" in again.output


def test_long_values_are_quoted_as_a_bounded_excerpt(tmp_path):
    spec = config("fir_differentiator", {})
    spec["name"] = "x" * 1_000_000
    path = tmp_path / "long.yaml"
    path.write_text(yaml.safe_dump(spec, width=2**31 - 1))
    result = _command("validate", str(path))
    assert result.returncode == 2
    assert len(result.stderr) < 600 and "xxx...xxx" in result.stderr, result.stderr[:600]


def test_an_alias_bomb_in_an_override_is_quoted_as_an_excerpt():
    bomb = "{" + ", ".join(f"l{i}: &l{i} [" + ", ".join([f"*l{i - 1}"] * 9 if i else
                                                      ["lol"] * 9) + "]" for i in range(7)) + "}"
    result = _command("validate", "configs/fir_differentiator.yaml", f"name={bomb}")
    assert result.returncode == 2 and "name: expected a non-empty string" in result.stderr
    assert len(result.stderr) < 600, len(result.stderr)


def test_a_valid_but_foreign_analysis_is_one_line(tmp_path):
    result = _command("validate", "configs/fir_differentiator.yaml", "analysis=perturbation")
    assert result.returncode == 2
    assert result.stderr.strip().splitlines() == [
        "error: configs/fir_differentiator.yaml: analysis: 'perturbation' takes none of the "
        "keys bands, max_n, max_taps, thresholds_db; they are keys of 'differentiator': is the "
        "analysis the file's?"]


@pytest.mark.parametrize("delay", [0.0, 0.05, 0.1, 0.2])
def test_ctrl_c_while_python_imports_is_one_line_and_exit_130(delay):
    """SIGINT ``delay`` + 5 ms after the child is about to call the console script's
    ``main``, while it imports click and the commands (about 0.3 s). A fixed sleep from the
    process' start raced the interpreter's own start-up (over 30 ms on a loaded machine: 3
    of 40 such runs got Python's default traceback before any line of estim had run), which
    no program can answer; so the child installs the handler as main's first line does, says
    so, and the clock starts there (a fixed 5 ms after 'in' raced main's own first line on a
    machine running two CI jobs: an interrupt before the launcher's ``try`` is now recorded
    and raised inside it, :func:`estim.util.interrupt.arm`)."""
    child = ("import signal, sys; from estim.cli import launch; from estim.util import interrupt; "
             "signal.signal(signal.SIGINT, interrupt.on_interrupt); "     # as main's first line
             "sys.stderr.write('in\\n'); sys.stderr.flush(); launch.main()")
    launch = [sys.executable, "-c", child, "validate", "configs/mosfet_saturation.yaml"]
    run = subprocess.Popen(launch, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                           text=True, preexec_fn=interruptible)
    assert run.stderr.readline() == "in\n"
    time.sleep(delay + 0.005)               # main's first line installs the handler
    run.send_signal(signal.SIGINT)
    _, err = run.communicate(timeout=60)
    assert run.returncode == 130, err
    assert err.strip().splitlines() == ["error: interrupted"], err


def test_ctrl_c_inside_clicks_argument_parsing_is_exit_130_not_aborted(monkeypatch, capsys):
    """A SIGINT that lands in click's own parsing, after the commands are imported and before
    any command runs (click's standalone mode prints "Aborted!" and exits 1 there), is one
    line and exit 130 like every other interrupt."""
    from estim.cli import entry, launch
    from estim.util import interrupt

    def interrupted_while_parsing(*args, **kwargs):
        interrupt.on_interrupt(signal.SIGINT, None)       # what the real SIGINT runs

    monkeypatch.setattr(entry.main, "make_context", interrupted_while_parsing)
    monkeypatch.setattr(sys, "argv", ["estim", "list"])
    import threading

    previous = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}
    hooks = sys.unraisablehook, threading.excepthook
    try:
        with pytest.raises(SystemExit) as stop:
            launch.main()
    finally:                    # this process' handlers and hooks as they were
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        sys.unraisablehook, threading.excepthook = hooks
        interrupt.INTERRUPTED[0] = interrupt.ARMED[0] = False
    assert stop.value.code == 130       # (click first ends the terminal's ^C line)
    assert capsys.readouterr().err.strip().splitlines() == ["error: interrupted"]


@pytest.mark.parametrize("argv, code, last", [
    (["--version"], 0, None),
    (["nosuch"], 2, "error: No such command 'nosuch'. (see 'estim --help')"),
    (["run"], 2, "error: Missing argument 'CONFIGS...'. (see 'estim run --help')"),
    (["table", "--nosuch"], 2, "error: No such option.*--nosuch.* \\(see 'estim table --help'\\)")])
def test_the_console_script_maps_clicks_outcomes_as_click_would(argv, code, last):
    """Click's exit codes, and its usage errors in the one-line form of every other error
    (with the command whose help to read)."""
    result = subprocess.run([sys.executable, "-c", "from estim.cli import launch; launch.main()",
                             *argv], cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert result.returncode == code, result.stderr
    if last:      # (click's wording of a message differs between its versions)
        lines = result.stderr.splitlines()
        assert len(lines) == 1 and (lines[0] == last or re.fullmatch(last, lines[0])), lines
    else:
        assert result.stdout.startswith("estim, version ")


def test_a_closed_output_pipe_is_a_quiet_exit_1():
    run = subprocess.Popen([sys.executable, "-c", "from estim.cli import launch; launch.main()",
                            "list"], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    run.stdout.close()                  # the reader went away, as `estim list | head -0`
    err = run.stderr.read().decode()
    assert run.wait(timeout=60) == 1, err
    assert [line for line in err.splitlines() if not line.startswith("project ")] == []


def test_a_valid_override_longer_than_a_file_name_is_an_override():
    values = ",".join(str(f) for f in range(1000, 1500, 10))
    override = f"input.frequencies_hz=[{values}]"
    assert len(override.encode()) > 255
    result = _command("validate", "configs/mosfet_saturation.yaml", override, "--max-work",
                      str(10**12))
    assert result.returncode == 0, result.stderr


def test_a_full_width_digit_in_a_shard_is_refused():
    result = CliRunner().invoke(main, ["run", "configs/fir_differentiator.yaml", "--shard",
                                       "\uff11/2", "--out", "/tmp/estim-never"])
    assert result.exit_code == 2 and "expected K/N" in result.output


@pytest.mark.parametrize("address", ["bogus://x", "127.0.0.1:notaport"])
def test_a_malformed_scheduler_address_is_exit_2(tmp_path, address):
    pytest.importorskip("distributed")
    result = _command("run", "configs/fir_differentiator.yaml", "--executor", "dask",
                      "--scheduler", address, "--out", str(tmp_path / "o"))
    assert result.returncode == 2, result.stderr
    assert result.stderr.startswith("error: cannot reach the Dask scheduler")
    assert len(result.stderr.strip().splitlines()) == 1


def test_a_manifest_naming_its_analysis_by_a_list_is_named_not_a_crash(stored):
    _, out = stored
    manifest = out / "tiny" / "manifest.json"
    data = json.loads(manifest.read_text())
    data["config"]["analysis"] = ["estimation"]
    manifest.write_text(json.dumps(data))
    for args in (["table", "rmse", "--results", str(out)],
                 ["report", "--results", str(out), "--out", str(out / "page.html")],
                 ["summary", "--results", str(out)]):
        result = _command(*args)
        assert result.returncode == 2, (args, result.stderr)
        assert "Traceback" not in result.stderr and len(result.stderr.splitlines()) == 1


def test_a_junk_stored_figure_or_an_unknown_table_id_is_named_and_exit_2(stored, rehash):
    """estim report on a PNG that is not an image, and estim table --thesis on a table whose
    table_id names no printed table, each end in one line naming the file (they were exit 3
    with PIL's or the package's own file name)."""
    _, out = stored
    figure = next((out / "tiny" / "figures").glob("*.png"))
    figure.write_text("junk")
    result = _command("report", "--results", str(out), "--out", str(out / "page.html"))
    assert result.returncode == 2, result.stderr
    assert f"tiny/figures/{figure.name}" in result.stderr and "Traceback" not in result.stderr
    table = out / "tiny" / "rmse.csv"
    lines = table.read_text().splitlines()
    head = lines[0].split(",").index("table_id")
    rows = [line.split(",") for line in lines[1:]]
    for row in rows:
        row[head] = "9.9"
    table.write_text("\n".join([lines[0], *(",".join(r) for r in rows)]) + "\n")
    rehash(out / "tiny")
    result = _command("table", "rmse", "--thesis", "--results", str(out))
    assert result.returncode == 2, result.stderr
    assert str(table) in result.stderr and "'9.9'" in result.stderr


def test_an_experiment_folder_given_as_results_is_named_as_such(stored):
    _, out = stored
    result = CliRunner().invoke(main, ["table", "rmse", "--results", str(out / "tiny")])
    assert result.exit_code == 2 and "is one experiment's folder" in result.output


def test_a_yaml_merge_key_merges_and_yields_to_explicit_keys():
    """``<<: *anchor`` (a YAML merge key) failed as 'could not determine a constructor'."""
    from estim.config.loading import load_yaml

    text = "a: &s {q: 1, r: 2}\nb:\n  <<: *s\n  r: 3\n"
    assert load_yaml(text, "m.yaml") == {"a": {"q": 1, "r": 2}, "b": {"q": 1, "r": 3}}


LAUNCH = "from estim.cli.launch import main; main()"


@pytest.mark.slow
def test_a_closed_stderr_or_a_narrow_terminal_encoding_does_not_end_a_command(tmp_path):
    """With stderr closed, a run died at its first progress line (exit 3, nothing written);
    on a latin-1 terminal estim summary died at its first en dash (exit 3)."""
    out = tmp_path / "o"
    closed = subprocess.run(["bash", "-c", f"{sys.executable} -c '{LAUNCH}' run "
                             f"configs/passive_network.yaml --quick --out {out} 2>&-"],
                            cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert closed.returncode == 0 and (out / "passive_network" / "manifest.json").is_file()
    narrow = subprocess.run([sys.executable, "-c", LAUNCH, "summary"], cwd=ROOT, timeout=120,
                            capture_output=True, env={**os.environ, "PYTHONIOENCODING": "latin-1"})
    assert narrow.returncode == 0, narrow.stderr
    assert b"ratio" in narrow.stdout


def test_a_cell_is_data_and_comes_back_as_it_went():
    """A work unit's value survives the cell format (``.npz`` plus JSON, no pickle) with its
    types: tuple keys, numpy arrays of every numeric kind, numpy and Python scalars, exact
    floats (nan, inf, the last bit) and estim's dataclasses; a value of another type is
    refused at once instead of written."""
    from estim.engine import cells
    from estim.experiments.shared.claims import Losses

    value = {("a", 1): [np.arange(3), np.array([True, False]), np.array([1 + 2j])],
             "x": (np.float64(0.1), 0.1 + 2**-54, float("nan"), float("-inf"), 2**70, None),
             "losses": Losses(np.array([1.0, 2.0]), np.array([False, True]))}
    tree, arrays = cells.encode(value)
    back = cells.decode(tree, arrays)
    assert back.keys() == value.keys() and isinstance(back["x"], tuple)
    assert type(back["x"][0]) is np.float64 and back["x"][1] == 0.1 + 2**-54
    assert np.isnan(back["x"][2]) and back["x"][3] == float("-inf") and back["x"][4] == 2**70
    assert [a.dtype for a in back[("a", 1)]] == [a.dtype for a in value[("a", 1)]]
    assert isinstance(back["losses"], Losses)
    assert np.array_equal(back["losses"].values, value["losses"].values)
    with pytest.raises(cells.CellError, match="not a type a cell holds"):
        cells.encode({"f": open})
    with pytest.raises(cells.CellError, match="numbers only"):
        cells.encode(np.array(["a", object()], dtype=object))


@pytest.mark.slow
def test_merge_never_runs_code_from_a_shard_folder(tmp_path):
    """A shard folder is what users share between machines: a pickle that would run a
    command, a cell file whose array is an object pickle, and a cell of another config put
    in a shard's cell folder are each refused by name and never loaded; the merged tables
    equal one run's."""
    path = tmp_path / "tiny.yaml"
    path.write_text(yaml.safe_dump(tiny_spec()))
    runner = CliRunner()
    shard = tmp_path / "s1"
    assert runner.invoke(main, ["run", str(path), "--out", str(shard), "--shard", "1/2",
                                "--quiet"]).exit_code == 0
    (folder,) = shard.glob(".tiny.cells-*")
    cells_ = sorted(folder.glob("cell-*.npz"))
    marker = tmp_path / "ran"

    class Payload:
        def __reduce__(self):
            return (os.system, (f"touch {marker}",))

    (folder / "cell-9.pkl").write_bytes(pickle.dumps(Payload()))
    buf = io.BytesIO()
    np.savez(buf, meta=np.frombuffer(b"{}", np.uint8), a0=np.array([Payload()], dtype=object))
    cells_[0].write_bytes(buf.getvalue())
    other = tmp_path / "other.yaml"
    spec = tiny_spec()
    spec["monte_carlo"]["seed"] = 99
    other.write_text(yaml.safe_dump(spec))
    assert runner.invoke(main, ["run", str(other), "--out", str(tmp_path / "o"), "--shard",
                                "1/2", "--quiet"]).exit_code == 0
    (foreign,) = sorted((tmp_path / "o").glob(".tiny.cells-*/cell-*.npz"))[:1]
    (folder / "cell-8.npz").write_bytes(foreign.read_bytes())
    merged = runner.invoke(main, ["merge", str(path), "--from", str(shard), "--out",
                                  str(tmp_path / "m"), "--quiet"])
    assert merged.exit_code == 0, merged.output
    assert not marker.exists()
    said = merged.output
    assert "cell-9.pkl (not a cell file's name)" in said
    assert f"{cells_[0].name} (not a cell file" in said
    assert "cell-8.npz (a cell of another config or estim version)" in said
    reference = runner.invoke(main, ["run", str(path), "--out", str(tmp_path / "r"),
                                     "--quiet"])
    assert reference.exit_code == 0
    assert ((tmp_path / "m" / "tiny" / "rmse.csv").read_bytes()
            == (tmp_path / "r" / "tiny" / "rmse.csv").read_bytes())


def test_report_tune_and_readme_refuse_what_they_must_not_write(tmp_path):
    """report --out, summary --readme: a file inside a result folder, a FIFO (which would
    block) and a name over the system's limit are one line and exit 2, before any work."""
    results = tmp_path / "results"
    shutil.copytree(ROOT / "results" / "mosfet_distortion", results / "mosfet_distortion")
    fifo = tmp_path / "pipe.md"
    os.mkfifo(fifo)
    runner = CliRunner()
    cases = [
        (["report", "--results", str(results), "--out",
          str(results / "mosfet_distortion" / "rmse.csv")], "inside the result folder"),
        (["report", "--results", str(results), "--out", str(fifo)], "not a regular file"),
        (["report", "--results", str(results), "--out", str(tmp_path / ("x" * 300))],
         "longer than the system allows"),
        (["summary", "--results", str(results), "--readme", str(fifo)], "not a regular file"),
        (["summary", "--results", str(results), "--readme", "/dev/zero"], "not a regular file"),
        (["tune", "configs/mosfet_saturation.yaml", "--estimator", "EKF", "--out",
          str(tmp_path / ("y" * 300))],
         "longer than the system allows"),
        (["summary", "--results", str(results), "--readme",
          str(results / "mosfet_distortion" / "claims.csv")], "inside the result folder"),
    ]
    for args, said in cases:
        result = runner.invoke(main, args)
        assert result.exit_code == 2, (args, result.output)
        lines = result.output.strip().splitlines()
        assert len(lines) == 1 and said in lines[0] and lines[0].startswith("error: "), lines
    assert (results / "mosfet_distortion" / "claims.csv").read_bytes() == (
        ROOT / "results" / "mosfet_distortion" / "claims.csv").read_bytes()


def test_summary_readme_makes_each_experiment_once_however_many_blocks(monkeypatch):
    """A README with 2,000 blocks of one experiment costs one experiment's summary, not
    2,000 (the work grows with the file, not with blocks times experiments)."""
    from estim.config.registry import ANALYSES
    from estim.report import summary

    calls = []
    made = summary.experiment

    def counted(folder, analyses):
        calls.append(folder.name)
        return made(folder, analyses)

    monkeypatch.setattr(summary, "experiment", counted)
    text = "<!-- summary: mosfet_distortion -->\n<!-- /summary -->\n" * 2000
    new, stale = summary.refresh(text, ROOT / "results", ANALYSES)
    assert calls == ["mosfet_distortion"] and len(stale) == 2000
    assert new.count("**mosfet_distortion**") == 2000


@pytest.mark.parametrize("line, said", [
    ("V5 n8 0 DC", "a source needs a value after DC"),
    ("R1 a 0 {" + "+".join(["1"] * 5000) + "}", "longer than 1000 characters"),
    ("R1 a 0 {" + "-" * 100_000 + "1}", "longer than 1000 characters"),
    ("R1 a 0 {0x10}", "'0x10' in '0x10' is not a SPICE number"),
    ("R1 a 0 {1_000}", "'1_000' in '1_000' is not a SPICE number"),
    ("R1 a 0 1e", "an exponent 'e' with no digits"),
    ("R1 a 0 1e3k", "both an exponent and a scale suffix"),
])
def test_a_malformed_netlist_line_is_a_netlist_error_with_its_line(line, said):
    """Each of these escaped as IndexError, RecursionError or MemoryError, or was read as
    a number Python knows and SPICE does not."""
    from estim.spice.parser import NetlistError, parse

    with pytest.raises(NetlistError) as caught:
        parse(f"title\n{line}\nC1 a 0 1p\n", "t.cir")
    assert str(caught.value).startswith("t.cir:2: ") and said in str(caught.value)


def test_a_long_netlist_is_read_and_its_duplicates_named():
    """60,000 elements (and as many continuation lines) parse, and a name defined twice
    among them is named with its line."""
    from estim.spice.parser import NetlistError, parse

    body = "".join(f"R{i} n{i} n{i + 1}\n+ 1k\n" for i in range(30_000))
    body += "".join(f"C{i} n{i} 0 1p\n" for i in range(30_000))
    net = parse("title\n" + body, "big.cir")
    assert len(net.elements) == 60_000
    with pytest.raises(NetlistError, match=r"big\.cir:\d+: element r7 is defined twice"):
        parse("title\n" + body + "R7 a 0 1\n", "big.cir")


# ----- issue 45: one reader of stored results, whole manifests, degenerate inputs, the API --------

def _edit_manifest(folder: Path, change) -> None:
    manifest = folder / "manifest.json"
    data = json.loads(manifest.read_text())
    change(data)
    manifest.write_text(json.dumps(data))


MANIFEST_DAMAGE = {
    "config removed": (lambda d: d.pop("config"), "no 'config' mapping"),
    "analysis changed": (lambda d: d["config"].update(analysis="field_study"),
                         "does not hash to its config_sha256"),
    "nan seed": (lambda d: d.update(seed=float("nan")), "'seed' is nan, not an integer"),
    "other seed": (lambda d: d.update(seed=d["seed"] + 1), "its config's"),
    "wrong table hash": (lambda d: d["files"].update({"rmse.csv": "0" * 64}),
                         "rmse.csv: not the file its manifest records"),
    "escaping entry": (lambda d: d["files"].update({"../x.csv": "0" * 64}),
                       "outside the folder's own files"),
}


@pytest.mark.parametrize("kind", sorted(MANIFEST_DAMAGE))
def test_a_damaged_manifest_gets_the_same_verdict_from_check_table_report_and_summary(
        stored, kind):
    """estim check compared only the config hash, so a manifest with its config removed, a
    changed analysis, a NaN seed or a wrong table hash passed it while table, report and
    summary refused the folder; now every command reads the folder one way."""
    path, out = stored
    change, said = MANIFEST_DAMAGE[kind]
    _edit_manifest(out / "tiny", change)
    checked = CliRunner().invoke(main, ["check", str(path), "--results", str(out)])
    assert checked.exit_code == 1 and said in checked.output, checked.output
    for args in (["table", "rmse", "--results", str(out)], ["summary", "--results", str(out)],
                 ["report", "--results", str(out), "--out", str(out.parent / "page.html")]):
        result = CliRunner().invoke(main, args)
        assert result.exit_code == 2, (args, result.output)
        assert said in result.output and "Traceback" not in result.output, (args, result.output)


def test_check_names_a_file_its_manifest_does_not_list(stored):
    path, out = stored
    (out / "tiny" / "extra.csv").write_text("a,b\n1,2\n")
    result = CliRunner().invoke(main, ["check", str(path), "--results", str(out)])
    assert result.exit_code == 1 and "extra.csv: not listed in its manifest" in result.output


@pytest.mark.parametrize("kind", ["fifo", "directory", "dangling", "device"])
def test_summary_refuses_a_stored_table_that_is_not_a_file_as_table_does(stored, kind):
    """estim summary silently left such a table out where table and report exit 2."""
    _, out = stored
    target = out / "tiny" / "claims.csv"
    target.unlink()
    if kind == "fifo":
        os.mkfifo(target)
    elif kind == "directory":
        target.mkdir()
    elif kind == "dangling":
        target.symlink_to(out / "nowhere.csv")
    else:
        target.symlink_to("/dev/zero")
    result = _command("summary", "--results", str(out))
    assert result.returncode == 2, result.stderr
    assert str(target) in result.stderr and len(result.stderr.strip().splitlines()) == 1


def test_an_edited_table_is_refused_by_name_and_an_agreeing_manifest_reaches_the_parser(
        stored, rehash):
    _, out = stored
    target = out / "tiny" / "rmse.csv"
    target.write_bytes(target.read_bytes().replace(b"\n", b"\r\n"))   # the same table
    result = CliRunner().invoke(main, ["table", "rmse", "--results", str(out)])
    assert result.exit_code == 2 and "sha256 differs" in result.output
    rehash(out / "tiny")
    assert CliRunner().invoke(main, ["table", "rmse", "--results", str(out)]).exit_code == 0


@pytest.mark.parametrize("output, said", [("v(o,o)", "a node and itself"),
                                          ("v(0)", "ground's voltage"),
                                          ("v(0,gnd)", "a node and itself")])
def test_an_identically_zero_netlist_output_is_refused(tmp_path, output, said):
    """``model.output: v(o,o)`` was accepted: gain_db -inf, a distortion of 2.75 %."""
    from estim.spice.netlist_class import model_class
    from estim.spice.parser import NetlistError

    net = tmp_path / "rc.cir"
    net.write_text("rc\nV1 in 0 DC 0\nR1 in o 1k\nC1 o 0 1u\n.end\n")
    with pytest.raises(NetlistError, match=said):
        model_class(net, ["V1"], output)


@pytest.mark.parametrize("name, key, value", [
    ("mosfet_saturation", "noise.measurement_sigma", 0.0),
    ("mosfet_saturation", "noise.measurement_sigma", 1e-300),
    ("dipole_field", "sensors.measurement_sigma", 1e-300),
    ("dipole_literal", "noise.measurement_sigma", 0.0),
    ("passive_network", "signals.0.sigma", 0.0),
])
def test_zero_noise_is_a_config_error_not_an_infinite_ratio(tmp_path, name, key, value):
    """A zero measurement noise gave inf ratios with no word; 1e-300 passed validation and
    the run died with LinAlgError."""
    path, result = validate_text(tmp_path, yaml.safe_dump(config(name, {key: value})))
    shown = key.replace(".0.", "[0].")
    assert_one_line_exit_2(result, path, shown, "expected a number >= 1e-12")


def _ekf():
    from estim import estimators
    return estimators.get("ekf")


@pytest.mark.parametrize("settings, key", [
    ({"Q": -1.0, "R": 0.1, "P0": 1.0}, "Q"), ({"Q": 0.1, "R": 0.0, "P0": 1.0}, "R"),
    ({"Q": 0.1, "R": -1.0, "P0": 1.0}, "R"), ({"Q": 0.1, "R": 0.1, "P0": -1.0}, "P0"),
    ({"Q": [[1.0, 2.0], [0.0, 1.0]], "R": 0.1, "P0": 1.0}, "Q"),
])
def test_the_apis_filters_make_the_configs_covariance_checks(settings, key):
    from estim.errors import SettingError

    for name in ("ekf", "ukf", "kronecker_ekf"):
        from estim import estimators
        with pytest.raises(SettingError) as got:
            estimators.get(name)(**settings)
        assert got.value.key == key, str(got.value)


def test_a_required_setting_given_as_none_is_refused():
    with pytest.raises(TypeError, match="missing required setting 'Q'"):
        _ekf()(Q=None, R=0.1, P0=1.0)


def test_numpy_numbers_are_settings_and_stored_as_plain_ones():
    ekf = _ekf()(Q=np.float64(0.01), R=np.array([0.1]), P0=np.eye(1), substeps=np.int64(2))
    assert type(ekf.substeps) is int and ekf.R == [0.1] and ekf.P0 == [[1.0]]


@pytest.mark.parametrize("dt", [0.0, -1e-4, float("nan"), float("inf"), "0.1", True])
def test_a_run_with_a_bad_time_step_is_refused_by_name(dt):
    from estim.errors import SettingError

    model = _toy_model()
    z, u = np.zeros((2, 5, model.n_outputs)), np.zeros((5, model.n_inputs))
    with pytest.raises(SettingError) as got:
        _ekf().example(model).run(model, z, u, dt)
    assert got.value.key == "dt"


@pytest.mark.parametrize("z_shape, u_shape, key", [
    ((5, 1), (5, 1), "z"), ((2, 5, 3), (5, 1), "z"), ((2, 5, 1), (4, 1), "u"),
    ((2, 5, 1), (3, 5, 1), "u"), ((2, 5, 1), (5, 7), "u"),
])
def test_a_run_with_arrays_of_the_wrong_shape_is_refused_by_name(z_shape, u_shape, key):
    from estim.errors import SettingError

    model = _toy_model()
    z_shape = tuple(model.n_outputs if s == 1 and i == len(z_shape) - 1 else s
                    for i, s in enumerate(z_shape))
    u_shape = tuple(model.n_inputs if s == 1 and i == len(u_shape) - 1 else s
                    for i, s in enumerate(u_shape))
    for name in ("ekf", "ukf"):
        from estim import estimators
        with pytest.raises(SettingError) as got:
            estimators.get(name).example(model).run(model, np.zeros(z_shape), np.zeros(u_shape),
                                                    1e-3)
        assert got.value.key == key, str(got.value)


def test_a_kf_whose_estimate_overflows_marks_the_run_broken():
    """A=1e308 returned NaN estimates with ``broken`` all False."""
    from estim import estimators

    kf = estimators.get("kf")(A=1e308, B=0.0, C=1.0, Q=0.01, R=0.1, P0=1.0, x0=[1.0])
    z = np.ones((3, 6, 1))
    out = kf.run(None, z, np.zeros((6, 1)))
    assert out.broken.all()
    assert np.isnan(out.y_hat[:, -1]).all()
    fine = estimators.get("kf")(A=0.5, B=0.0, C=1.0, Q=0.01, R=0.1, P0=1.0, x0=[1.0])
    assert not fine.run(None, z, np.zeros((6, 1))).broken.any()


def _toy_model():
    from estim import models
    return models.get("mosfet_ekv")()


def test_the_apis_overrides_take_the_command_lines_forms_and_numpy_numbers():
    import estim
    from estim.errors import UsageError

    exp = estim.experiment("mosfet_saturation", {"estimators[0].settings.substeps": 2},
                           runs=np.int64(3), seed=np.int64(7))
    assert exp.spec["estimators"][0]["settings"]["substeps"] == 2
    assert exp.spec["monte_carlo"]["runs"] == 3 and type(exp.spec["monte_carlo"]["runs"]) is int
    with pytest.raises(UsageError, match="key 1 is not a key path"):
        estim.experiment("mosfet_saturation", {1: 2})
    with pytest.raises(UsageError, match="expected a mapping"):
        estim.experiment("mosfet_saturation", [("a", 1)])


def test_sigterm_is_one_line_exit_143_and_leaves_no_folder(tmp_path):
    path = tmp_path / "tiny.yaml"
    spec = tiny_spec(runs=200, periods=40)
    spec["input"]["frequencies_hz"] = [100, 1000, 10000]
    path.write_text(yaml.safe_dump(spec))
    run = estim("run", str(path), "--out", str(tmp_path / "out"), "--jobs", "2", cwd=tmp_path)
    assert "work units" in started(run)
    time.sleep(0.5)
    run.send_signal(signal.SIGTERM)
    assert run.wait(timeout=60) == 143
    rest = run.stderr.read()
    assert rest.strip().splitlines() == ["error: terminated"], rest
    assert not (tmp_path / "out" / "tiny").exists()


def test_an_interrupt_while_python_exits_is_silent_in_the_hooks():
    """A Ctrl-C that lands while the interpreter joins a pool's thread at exit printed a
    traceback of 4 lines after the command's own output (1 of 9 trials)."""
    import threading
    import types

    from estim.cli import launch

    saved = sys.unraisablehook, threading.excepthook
    err = io.StringIO()
    try:
        launch._quiet_hooks()
        old_err, sys.stderr = sys.stderr, err
        try:
            sys.unraisablehook(types.SimpleNamespace(exc_value=KeyboardInterrupt(),
                                                     exc_type=KeyboardInterrupt))
            threading.excepthook(types.SimpleNamespace(exc_value=OSError(28, "No space"),
                                                       exc_type=OSError))
            threading.excepthook(types.SimpleNamespace(exc_value=ValueError("odd"),
                                                       exc_type=ValueError))
        finally:
            sys.stderr = old_err
    finally:
        sys.unraisablehook, threading.excepthook = saved
    assert err.getvalue().splitlines() == [
        "error: ValueError: odd (in a background thread; estim --debug shows the traceback)"]


def test_a_hung_ngspice_is_stopped_within_its_limit_and_the_limit_grows_with_the_run(
        tmp_path, monkeypatch):
    from estim.spice import ngspice
    from estim.spice.ngspice import NgspiceError

    assert ngspice.timeout(0) == ngspice.TIMEOUT_BASE
    assert ngspice.timeout(10_000) > ngspice.timeout(100) > ngspice.timeout(0)
    fake = tmp_path / "ngspice"
    pid = tmp_path / "pid"
    fake.write_text(f"#!/bin/sh\necho $$ > {pid}\nexec sleep 60\n")
    fake.chmod(0o755)
    monkeypatch.setattr(ngspice, "TIMEOUT_BASE", 1.0)
    start = time.monotonic()
    with pytest.raises(NgspiceError, match="took more than 1 s"):
        ngspice._run("* deck\n.end\n", tmp_path, str(fake))
    assert time.monotonic() - start < 20
    gone = int(pid.read_text())
    with pytest.raises(ProcessLookupError):
        for _ in range(50):
            os.kill(gone, 0)
            time.sleep(0.1)


@pytest.mark.parametrize("value", [float("nan"), float("inf"), 1e300, "0.4"])
def test_a_model_made_in_code_checks_its_parameters_as_a_config_does(value):
    """``V_IN=nan`` gave a RuntimeError from the steady-state search naming no parameter."""
    from estim import models
    from estim.errors import ParameterError

    with pytest.raises(ParameterError, match="V_IN: expected"):
        models.get("mosfet_ekv")(V_IN=value)
    assert models.get("mosfet_ekv")(V_IN=np.float64(0.4)).params.V_IN == 0.4


def test_an_over_long_netlist_path_is_a_config_error(tmp_path):
    """A 5,000-character ``model.netlist`` ended in exit 3 (File name too long)."""
    spec = yaml.safe_load((ROOT / "configs" / "netlist" / "mosfet_saturation.yaml").read_text())
    spec["model"]["netlist"] = "a" * 5000 + ".cir"
    path, result = validate_text(tmp_path, yaml.safe_dump(spec))
    assert_one_line_exit_2(result, path, "model.netlist", "a path longer than")


@pytest.mark.parametrize("sig, code, line", [(signal.SIGTERM, 143, "error: terminated"),
                                             (signal.SIGINT, 130, "error: interrupted")])
def test_stopping_estim_spice_stops_its_ngspice_too(tmp_path, sig, code, line):
    """A SIGTERM to estim left its ngspice running (Python's default SIGTERM ends the
    process at once, so nothing stopped the child)."""
    fake = tmp_path / "ngspice"
    pid = tmp_path / "pid"
    fake.write_text(f"#!/bin/sh\necho $$ > {pid}\nexec sleep 120\n")
    fake.chmod(0o755)
    run = subprocess.Popen([sys.executable, "-m", "estim", "spice",
                            str(ROOT / "configs" / "netlist" / "mosfet_saturation.yaml"),
                            "--ngspice", str(fake)], cwd=tmp_path, stdout=subprocess.PIPE,
                           stderr=subprocess.PIPE, text=True, preexec_fn=interruptible)
    deadline = time.time() + 120
    while not pid.exists() and time.time() < deadline and run.poll() is None:
        time.sleep(0.1)
    assert pid.exists(), run.communicate()
    time.sleep(0.3)
    run.send_signal(sig)
    assert run.wait(timeout=60) == code
    assert run.stderr.read().strip().splitlines()[-1:] == [line]
    child = int(pid.read_text())
    for _ in range(50):
        try:
            os.kill(child, 0)
        except ProcessLookupError:
            break
        time.sleep(0.1)
    else:
        os.kill(child, signal.SIGKILL)
        pytest.fail("ngspice outlived estim")


def test_a_full_disk_under_report_or_summary_is_one_line_and_exit_2(tmp_path, monkeypatch):
    """report --out and summary --readme exited 3 on a full disk where run, tune and merge
    exit 2 in the same place."""
    import errno

    from estim import store as estim_store

    results = tmp_path / "results"
    shutil.copytree(ROOT / "results" / "mosfet_distortion", results / "mosfet_distortion")
    readme = tmp_path / "README.md"
    readme.write_text("<!-- summary: mosfet_distortion -->\nold\n<!-- /summary -->\n")

    def full(path, data):
        raise OSError(errno.ENOSPC, "No space left on device", str(path))

    monkeypatch.setattr(estim_store, "atomic_write_bytes", full)
    for args in (["report", "--results", str(results), "--out", str(tmp_path / "page.html")],
                 ["summary", "--results", str(results), "--readme", str(readme)]):
        result = CliRunner().invoke(main, args)
        assert result.exit_code == 2, (args, result.output)
        lines = result.output.strip().splitlines()
        assert len(lines) == 1 and "No space left on device" in lines[0], lines
    assert "old" in readme.read_text()
