import numpy as np
import pandas as pd
import pytest

from estim import reference
from estim.errors import ReferenceJoinError
from estim.experiments import estimation
from estim.reference.tablespec import TableSpec
from estim.report import tables

RMSE = estimation.TABLES["rmse"]


def rmse_rows(ekf, rls, s_no=1):
    base = {"table_id": "3.2", "s_no": s_no, "measurement": "noisy", "noise_reading": "sigma",
            "noise_param": 0.25,
            "noise_sigma": 0.25, "frequency_hz": 100.0, "samples_per_period": 10.0,
            "rmse_se": 0.01, "runs": 30}
    return pd.DataFrame([{**base, "estimator": "EKF", "rmse": ekf, "diverged": 0},
                         {**base, "estimator": "RLS", "rmse": rls, "diverged": 0}])


def all_rows_of_table_3_2(value=0.5):
    ref = reference.reference_table("3.2")
    return pd.DataFrame({"table_id": "3.2", "s_no": ref["s_no"], "noise_reading": "sigma",
                         "noise_param": ref["noise_param_value"], "noise_sigma": 0.0,
                         "frequency_hz": ref["frequency_hz"], "samples_per_period": 10.0,
                         "estimator": ref["estimator"], "rmse": value, "rmse_se": 0.0,
                         "runs": 30, "diverged": 0})


def test_with_reference_puts_printed_value_and_ratio_beside_ours():
    out = reference.with_reference(all_rows_of_table_3_2(), RMSE)
    assert list(out["thesis_rmse"][:2]) == [0.4024, 0.6043]
    np.testing.assert_allclose(out["ratio_rmse"][:2], [0.5 / 0.4024, 0.5 / 0.6043])


def test_unmatched_reference_row_is_an_error_naming_table_and_row():
    part = rmse_rows(0.2012, 0.6043)
    with pytest.raises(ReferenceJoinError, match=r"Table 3.2: row 3 \(s_no=2, estimator=EKF\)"):
        reference.with_reference(part, RMSE)
    out = reference.with_reference(part, RMSE, allow_unmatched=True)
    assert list(out["thesis_rmse"]) == [0.4024, 0.6043]


def test_a_key_that_repeats_in_the_reference_is_an_error():
    # Table 4.2 repeats (s_no, estimator) over its W/L columns: joining on it is ambiguous
    spec = TableSpec("rmse.csv", ("table_id", "s_no", "estimator"), ("rmse",),
                     reference=("rmse",), join=(("s_no", ("s_no",)), ("estimator",
                                                                        ("estimator",))))
    ours = pd.DataFrame({"table_id": ["4.2"], "s_no": [1], "estimator": ["EKF"],
                         "rmse": [0.001]})
    with pytest.raises(ReferenceJoinError, match=r"Table 4.2: key \['s_no', 'estimator'\] "
                                                 r"repeats in row 1"):
        reference.with_reference(ours, spec)


def test_thesis_tables_ship_with_the_package():
    t = reference.reference_table("3.1")
    assert len(t) == 12 and set(t["estimator"]) == {"EKF", "RLS"}


def test_render_latex_markdown_and_text_are_fit_for_a_paper():
    import pandas as pd


    df = pd.DataFrame({"frequency_hz": [100.0, 10000.0], "noise_param": [0.25, 1e-7],
                       "estimator": ["EKF (fitted Q)", "x_1 & 50%"],
                       "s_no": pd.array([1, None], dtype="Int64")})
    latex = tables.render(df, "latex")
    assert r"frequency\_hz" in latex and r"x\_1 \& 50\%" in latex
    assert r"\toprule" in latex and r"\bottomrule" in latex and "booktabs" in latex
    assert "10000" in latex and "e+04" not in latex and "1e-07" in latex
    assert latex.count(r" \\") == 3                      # header and two rows
    text = tables.render(df, "text")
    assert "10000" in text and "--" in text
    wide = pd.DataFrame({f"column_{i}_with_a_long_name": [1.5] for i in range(12)})
    assert max(len(line) for line in tables.render(wide, "text").splitlines()) <= 100
    md = tables.render(df, "markdown")
    assert md.splitlines()[1].startswith("|---") or "--:" in md.splitlines()[1]
    assert tables.latex_escape("a<b>c|d") == r"a\textless{}b\textgreater{}c\textbar{}d"
    assert tables.number(np.float32("nan")) == "--" and tables.number(np.float32(2.5)) == "2.5"


def test_text_layout_is_pandas_to_string_without_its_cut_of_long_cells():
    import pandas as pd


    rng = np.random.default_rng(3)
    for columns in (1, 3, 9, 14, 30):
        df = pd.DataFrame({f"c{i}" + "x" * int(rng.integers(0, 15)): rng.normal(size=7) * 10.0**i
                           for i in range(columns)})
        df["label"] = [f"estimator {k}" for k in range(7)]
        expected = df.astype(object).map(tables.number).to_string(
            index=False, line_width=tables.TEXT_WIDTH)
        assert tables.render(df, "text") == expected
    long = "strip Kalman, model from the clean image, on line, wide strips"
    text = tables.render(pd.DataFrame({"estimator": [long, "EKF"], "rmse": [0.1, 0.2]}), "text")
    assert long in text and "..." not in text


def test_table_of_named_experiments_and_the_thesis_view_leaves_out_unprinted_ones():
    """estim table METRIC EXPERIMENT... prints just those; --thesis leaves out the
    experiments with no printed table and names them in one line; a misspelled name is a
    usage error with a did-you-mean."""
    from pathlib import Path

    from click.testing import CliRunner

    from estim.cli.main import main

    results = str(Path(__file__).resolve().parents[1] / "results")
    one = CliRunner().invoke(main, ["table", "rmse", "mosfet_saturation", "--results", results])
    assert one.exit_code == 0
    heads = [line for line in one.output.splitlines() if line.startswith("== ")]
    assert len(heads) == 1 and heads[0].startswith("== mosfet_saturation:")
    every = CliRunner().invoke(main, ["table", "rmse", "--thesis", "--results", results])
    assert every.exit_code == 0
    last = every.output.strip().splitlines()[-1]
    assert last.startswith("(--thesis: left out ") and "mosfet_input_derivative" in last
    assert "== mosfet_input_derivative:" not in every.output
    alone = CliRunner().invoke(main, ["table", "rmse", "mosfet_input_derivative", "--thesis",
                                      "--results", results])
    assert alone.exit_code == 0 and alone.output.strip().splitlines() == [
        "(--thesis: left out 1 experiment(s) with no printed rmse table to compare with: "
        "mosfet_input_derivative; leave out --thesis to see them)"]
    typo = CliRunner().invoke(main, ["table", "rmse", "mosfet_saturaton", "--results", results])
    assert typo.exit_code == 2 and "did you mean 'mosfet_saturation'" in typo.output


def test_a_text_table_fits_the_width_with_the_thesis_value_beside_the_keys():
    """estim table rmse mosfet_saturation --thesis in 100 columns: every line fits; the
    columns with one value are said once, the keys the others determine are left out,
    ours, the thesis' value and the ratio stand beside the keys, and the columns that did
    not fit are named. --width 0 keeps every column."""
    from pathlib import Path

    from click.testing import CliRunner

    from estim.cli.main import main

    results = str(Path(__file__).resolve().parents[1] / "results")
    args = ["table", "rmse", "mosfet_saturation", "--thesis", "--results", results]
    out = CliRunner().invoke(main, [*args, "--width", "100"])
    assert out.exit_code == 0
    lines = out.output.splitlines()
    assert max(map(len, lines)) <= 100
    header = next(line for line in lines if "estimator" in line and "thesis_rmse" in line)
    names = header.split()
    assert names.index("rmse") + 1 == names.index("thesis_rmse")
    assert names.index("thesis_rmse") + 1 == names.index("ratio_rmse")
    text = " ".join(out.output.split())
    assert "(in every row: table_id = 3.2," in text and "left out for a width of 100:" in text
    ekf = next(line for line in lines if " EKF " in line and " 0.4024 " in line)
    assert ekf.split()[-len(names):][names.index("thesis_rmse")] == "0.4024"
    full = CliRunner().invoke(main, [*args, "--width", "0"])
    assert full.exit_code == 0 and "regime_fraction" in full.output
    assert "left out" not in full.output.split("==")[1]



def _same_cells(a: list, b: list) -> bool:
    from estim.util.columns import is_missing

    return all((is_missing(x) and is_missing(y)) or (x == y and type(x) is type(y))
               for x, y in zip(a, b, strict=True))


def test_plain_columns_read_every_stored_and_printed_table_as_pandas_does():
    """estim table reads CSV without pandas: every stored table and every printed one
    gives the same column kinds and values as pandas.read_csv, and writes back the same
    CSV."""
    from pathlib import Path

    from estim.store.read import read_columns, read_table
    from estim.util.columns import Table

    root = Path(__file__).resolve().parents[1]
    files = [f for m in sorted((root / "results").glob("*/manifest.json"))
             for f in sorted(m.parent.rglob("*.csv"))]
    assert len(files) > 50
    for path in files:
        frame, plain = read_table(path), read_columns(path)
        ours = Table.from_frame(frame)
        assert ours.kinds == plain.kinds, path
        for name in ours.names:
            assert _same_cells(ours[name], plain[name]), (path, name)
        assert plain.to_csv() == frame.to_csv(index=False), path
    for path in sorted((root / "core" / "reference").glob("table_*.csv")):
        table_id = path.stem[len("table_"):].replace("_", ".")
        frame, plain = reference.reference_table(table_id), reference.reference_columns(table_id)
        ours = Table.from_frame(frame)
        assert ours.kinds == plain.kinds, path
        for name in ours.names:
            assert _same_cells(ours[name], plain[name]), (path, name)


def test_plain_columns_type_cells_as_pandas_does():
    """The cases the stored tables may lack: a missing cell in an integer, boolean or text
    column, a column of missing cells only, infinities, text that looks like a number."""
    import io

    from estim.util.columns import Table

    text = ("a,b,c,d,e,f,g,h\n1,True,x,,inf,1_0,1.5,01\n,False,,,-inf,2,nan,2\n"
            "3,,y,,1e3,3, 4,3\n")
    frame = pd.read_csv(io.StringIO(text), keep_default_na=False,
                        na_values=["", "NaN", "nan", "<NA>"])
    plain, ours = Table.from_csv(text), Table.from_frame(frame)
    assert plain.kinds == ours.kinds
    for name in ours.names:
        assert _same_cells(ours[name], plain[name]), name
    assert plain.to_csv() == frame.to_csv(index=False)
    both = Table.concat([plain.select(["a", "b"]), plain.select(["c"])])
    together = pd.concat([frame[["a", "b"]], frame[["c"]]], ignore_index=True)
    assert both.kinds == Table.from_frame(together).kinds
    assert both.to_csv() == together.to_csv(index=False)
