from pathlib import Path

import pandas as pd
import pytest

from estim import store
from estim.engine import compare
from estim.store import folders


def test_atomic_write_leaves_old_file_when_interrupted(tmp_path, monkeypatch):
    target = tmp_path / "rmse.csv"
    target.write_text("old\n")

    def boom(src, dst):
        raise KeyboardInterrupt

    monkeypatch.setattr(folders.os, "replace", boom)
    with pytest.raises(KeyboardInterrupt):
        store.atomic_write_bytes(target, b"new half table")
    assert target.read_text() == "old\n"
    assert [p.name for p in tmp_path.iterdir()] == ["rmse.csv"]


def test_compare_tables_uses_column_tolerances():
    a = pd.DataFrame({"estimator": ["EKF"], "rmse": [1.0], "runs": [5]})
    b = pd.DataFrame({"estimator": ["EKF"], "rmse": [1.0 + 1e-7], "runs": [5]})
    assert compare.compare_tables(a, b, {"rmse": {"rtol": 1e-6}}) == []
    diffs = compare.compare_tables(a, b, {})
    assert [d["column"] for d in diffs] == ["rmse"]
    c = pd.DataFrame({"estimator": ["RLS"], "rmse": [1.0], "runs": [5]})
    assert [d["column"] for d in compare.compare_tables(a, c, {})] == ["estimator"]


def test_an_infinity_matches_only_itself_under_any_tolerance():
    """A stored inf admits no finite value (|x - inf| <= rtol |inf| would), nor the reverse;
    inf matches inf of its sign, NaN matches NaN."""
    inf, nan = float("inf"), float("nan")
    stored = pd.DataFrame({"rmse": [inf, 1.0, inf, -inf, nan], "rmse_se": [0.1] * 5})
    new = pd.DataFrame({"rmse": [5.0, inf, inf, inf, nan], "rmse_se": [0.1] * 5})
    tol = {"rmse": {"rtol": 1e-6, "atol": 1e-9, "se": 4.0}}
    assert [d["row"] for d in compare.compare_tables(stored, new, tol)] == [0, 1, 3]


def test_statistical_tolerances():
    nan = float("nan")
    stored = pd.DataFrame({"rmse": [0.30, 0.30, nan], "rmse_se": [0.01, 0.01, nan],
                           "runs": [30, 28, 0], "diverged": [0, 2, 30]})
    new = pd.DataFrame({"rmse": [0.33, 0.40, 0.22], "rmse_se": [0.01, 0.01, nan],
                        "runs": [30, 30, 1], "diverged": [0, 0, 29]})
    tol = {"rmse": {"se": 4.0}, "diverged": {"binomial": 4.0, "trials": ["runs", "diverged"]},
           "runs": {"binomial": 4.0, "trials": ["runs", "diverged"]}}
    diffs = compare.compare_tables(stored, new, tol)
    # 0.03 is 2.1 combined SEs: passes; 0.10 is 7.1: fails; the one-run mean is not compared
    assert [(d["row"], d["column"]) for d in diffs] == [(1, "rmse")]
    # two zero counts must agree exactly; 2 -> 0 of 30 is within 4 binomial deviations
    zero = pd.DataFrame({"rmse": [0.3], "rmse_se": [0.01], "runs": [30], "diverged": [0]})
    one = zero.assign(diverged=[1], runs=[29])
    assert compare.compare_tables(zero, zero, tol) == []
    assert compare.compare_tables(zero, one, tol) == []
    assert [d["column"] for d in compare.compare_tables(zero, one, {})] == ["runs", "diverged"]
    assert compare.compare_tables(stored, new, {**tol, "rmse": {"skip": "why"}}) == []


def test_a_file_where_the_result_folder_goes_is_refused_before_any_work(tmp_path):
    """A run into ``--out`` whose ``<name>`` is a file used to swap the file away into a
    hidden staging name after the work; it is refused on opening, and the file is kept."""
    from estim.errors import UsageError

    (tmp_path / "exp").write_text("mine\n")
    with pytest.raises(UsageError, match="exists and is not a folder"):
        with store.ResultFolder(tmp_path, "exp"):
            pass
    assert (tmp_path / "exp").read_text() == "mine\n"
    (tmp_path / "other").mkdir()
    (tmp_path / ".other.lock").mkdir()
    with pytest.raises(UsageError, match="cannot open the lock file"):
        with store.ResultFolder(tmp_path, "other"):
            pass


def test_an_atomic_write_never_replaces_a_fifo_a_device_or_a_folder(tmp_path):
    """estim tune --out /dev/full, run as root, replaced the device with a regular file."""
    import os

    from estim.errors import UsageError

    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    (tmp_path / "folder").mkdir()
    for target in (fifo, tmp_path / "folder"):
        with pytest.raises(UsageError, match="not a regular file; not replaced"):
            store.atomic_write_bytes(target, b"x")
    assert fifo.is_fifo() and (tmp_path / "folder").is_dir()
    (tmp_path / "real.yaml").write_text("old")
    (tmp_path / "link.yaml").symlink_to(tmp_path / "real.yaml")
    store.atomic_write_bytes(tmp_path / "link.yaml", b"new")          # written through the link
    assert (tmp_path / "link.yaml").is_symlink() and (tmp_path / "real.yaml").read_text() == "new"


def test_git_ignores_the_run_record_and_the_machine_files_but_not_the_manifest():
    """A reproduce on the machine kind that made results/ leaves git clean: what changes from
    run to run (run.json, machine/) is ignored; the manifest and the tables are tracked."""
    import subprocess

    root = Path(__file__).resolve().parents[1]
    if not (root / ".git").exists():
        pytest.skip("not a git checkout")
    paths = ["results/kronecker_burden/run.json", "results/kronecker_burden/machine/timing.csv",
             "results/kronecker_burden/manifest.json", "results/kronecker_burden/slopes.csv"]
    out = subprocess.run(["git", "-C", str(root), "check-ignore", "--no-index", *paths],
                         capture_output=True, text=True, check=False)
    assert out.stdout.split() == paths[:2]


def test_every_stored_manifest_records_its_config_as_todays_settings_read_it():
    """Each shipped config's stored manifest hashes the config as today's settings fill it
    (a setting added since, at its default, included): otherwise the README's first command
    rewrites the manifest and leaves git status dirty on a fresh clone."""
    import json

    from estim import store
    from estim.config.loading import load_file

    root = Path(__file__).resolve().parents[1]
    stale = []
    for path in sorted((root / "configs").glob("**/*.yaml")):
        if "fitted" in path.parts:
            continue
        exp = load_file(path)
        manifest = root / "results" / exp.name / "manifest.json"
        if not manifest.is_file():
            continue
        if json.loads(manifest.read_text())["config_sha256"] != store.spec_hash(exp.spec):
            stale.append(exp.name)
    assert not stale, f"re-run to refresh their manifests: {stale}"
