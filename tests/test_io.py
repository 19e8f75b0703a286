import pandas as pd
import pytest

from core import io


def test_atomic_write_leaves_old_file_when_interrupted(tmp_path, monkeypatch):
    target = tmp_path / "rmse.csv"
    target.write_text("old\n")

    def boom(src, dst):
        raise KeyboardInterrupt

    monkeypatch.setattr(io.os, "replace", boom)
    with pytest.raises(KeyboardInterrupt):
        io.atomic_write_bytes(target, b"new half table")
    assert target.read_text() == "old\n"
    assert [p.name for p in tmp_path.iterdir()] == ["rmse.csv"]


def test_compare_tables_uses_column_tolerances():
    a = pd.DataFrame({"estimator": ["EKF"], "rmse": [1.0], "runs": [5]})
    b = pd.DataFrame({"estimator": ["EKF"], "rmse": [1.0 + 1e-7], "runs": [5]})
    assert io.compare_tables(a, b, {"rmse": {"rtol": 1e-6}}) == []
    diffs = io.compare_tables(a, b, {})
    assert [d["column"] for d in diffs] == ["rmse"]
    c = pd.DataFrame({"estimator": ["RLS"], "rmse": [1.0], "runs": [5]})
    assert [d["column"] for d in io.compare_tables(a, c, {})] == ["estimator"]
