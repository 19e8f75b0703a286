"""Figures a researcher can put in a paper: diverged filters named, legends off the data,
readable windows, units in titles."""

import numpy as np

from estim.experiments.shared import plots


def _trace(n=400, f=1000.0, dt=1e-4):
    t = dt * np.arange(1, n + 1)
    actual = np.sin(2 * np.pi * f * t)
    broken = actual.copy()
    broken[250:] = np.inf
    wild = actual.copy()
    wild[100:] = 50.0
    return {"t": t, "source": actual, "clean": actual, "actual": actual, "z": actual + 0.1,
            "y_hat": {"EKF": actual + 0.01, "broken": broken, "wild": wild}}


def test_estimates_name_diverged_filters_and_keep_legends_off_the_data():
    fig = plots.estimates(_trace(), "test", period_s=1e-3)
    axes = fig.axes
    assert len(axes) == 4                        # input, whole record, last periods, errors
    fig.canvas.draw()
    labels = [t.get_text() for t in axes[1].get_legend().get_texts()]
    assert any(label.startswith("broken (leaves the axis at 25") for label in labels), labels
    assert any(label.startswith("wild (leaves the axis at 10") for label in labels), labels
    assert "EKF" in labels
    for ax in axes:
        assert ax.get_legend().get_window_extent().x0 >= ax.get_window_extent().x1
    start, end = axes[2].get_xlim()
    assert end - start < 4.0                              # ms: three periods of 1 ms, zoomed


def _narrow_trace(n=400, dt=1e-4):
    """Fig 3.4's case: an actual signal 0.02 V wide, noisy readings and filters whose
    estimates stray 0.1 V from it, one that runs away and one off from the start."""
    rng = np.random.default_rng(0)
    t = dt * np.arange(1, n + 1)
    actual = 0.97 + 0.01 * np.sin(2 * np.pi * 1000 * t)
    z = actual + 0.1 * rng.standard_normal(n)
    runaway = actual + np.where(t > 0.02, np.exp((t - 0.02) * 2000), 0.0)
    return {"t": t, "source": actual, "clean": actual, "actual": actual, "z": z,
            "y_hat": {"EKF": actual + 0.08 * rng.standard_normal(n), "RLS": 0.5 * (z + actual),
                      "runaway": runaway, "offset": actual + 40.0}}


def _estimate_lines(ax):
    return [line for line in ax.get_lines()
            if not line.get_label().startswith(("measurement", "actual", "_"))]


def test_every_plotted_estimate_has_points_inside_its_axes():
    for fig in (plots.estimates(_narrow_trace(), "t", period_s=1e-3),
                plots.estimates_clipped(_narrow_trace(), "t")):
        for ax in fig.axes[1:]:
            lo, hi = ax.get_ylim()
            for line in _estimate_lines(ax):
                y = np.asarray(line.get_ydata(), float)
                assert np.any(np.isfinite(y) & (y >= lo) & (y <= hi)), (ax.get_title(),
                                                                         line.get_label())
        whole, zoom = fig.axes[1], fig.axes[2]
        drawn = {line.get_label().split(" (")[0] for line in _estimate_lines(whole)}
        assert {"EKF", "RLS", "runaway"} <= drawn           # the axis spans the estimates
        lo, hi = whole.get_ylim()
        assert hi - lo > 0.2                                # not held to the actual's 0.02 V
        assert "off the axis throughout: offset" in whole.get_title()
        assert zoom.get_ylim()[1] - zoom.get_ylim()[0] < 0.05     # the waveform, readable
        assert fig.axes[3].get_yscale() == "log"            # and each estimate's error


def test_series_says_when_every_run_diverged():
    t = np.arange(1, 11) * 1e-3
    fig = plots.running_rmse({"t": t, "running_rmse": {"EKF": np.full(10, np.nan),
                                                        "RLS": np.ones(10)}}, "test")
    labels = [x.get_text() for x in fig.axes[0].get_legend().get_texts()]
    assert labels == ["EKF (no finite value: every run diverged)", "RLS"]


def test_parameters_carry_their_units():
    assert plots.with_unit("L_1", 6e-6) == "L_1 = 6 \u00b5H"
    assert plots.with_unit("R_E", 80.0) == "R_E = 80 \u03a9"
    assert plots.with_unit("C_GX", 1e-12) == "C_GX = 1 pF"
    assert plots.with_unit("eta", 1.3) == "eta = 1.3"


def test_figure_kinds_choose_what_an_estimation_run_draws(tmp_path):
    """figures.kinds: [rmse] draws the running-RMSE figure alone under its file name, [] none
    (and the tables are the same bytes either way: figures draw from their own batches); a
    kind estim does not draw is one error naming the key."""
    import yaml
    from click.testing import CliRunner
    from test_cli import tiny_config

    from estim.cli.main import main

    folders = {}
    for label, kinds in (("one", ["rmse"]), ("none", [])):
        spec = tiny_config(**{"figures.kinds": kinds})
        path = tmp_path / f"{label}.yaml"
        path.write_text(yaml.safe_dump(spec))
        result = CliRunner().invoke(main, ["run", str(path), "--out", str(tmp_path / label),
                                           "--quiet", "--jobs", "1"])
        assert result.exit_code == 0, result.output
        folders[label] = tmp_path / label / "tiny"
    names = spec["figures"]["names"]
    drawn = sorted(p.name for p in (folders["one"] / "figures").glob("*.png"))
    assert drawn == [f"{names['rmse']}.png"]
    assert not list(folders["none"].rglob("*.png"))
    assert (folders["one"] / "rmse.csv").read_bytes() == (folders["none"] / "rmse.csv").read_bytes()
    bad = tmp_path / "bad.yaml"
    bad.write_text(yaml.safe_dump(tiny_config(**{"figures.kinds": ["rmse", "bode"]})))
    result = CliRunner().invoke(main, ["validate", str(bad)])
    assert result.exit_code == 2 and "figures.kinds[1]" in result.output
    assert str(bad) in result.output and "Traceback" not in result.output
    bad.write_text(yaml.safe_dump(tiny_config(**{"figures.kinds": "rmse"})))
    result = CliRunner().invoke(main, ["validate", str(bad)])
    assert result.exit_code == 2 and "figures.kinds" in result.output and str(bad) in result.output
