"""The commands that read what is stored or declared: tables, summaries, the report page,
the settings, the configs, and a config's validation."""

from __future__ import annotations

import sys
from pathlib import Path

import click

from estim import store
from estim.cli import output, project
from estim.cli.group import fail
from estim.cli.options import NamedPath
from estim.config import loading as config
from estim.config.registry import ANALYSES
from estim.errors import UsageError

MAX_README_BYTES = 16 << 20
"""The largest file ``summary --readme`` reads."""


@click.command(name="report")
@click.option("--results", type=click.Path(file_okay=False, path_type=Path),
              help="Folder of stored results [default: the project's results/].")
@click.option("--out", type=NamedPath(dir_okay=False, path_type=Path), default="report.html",
              show_default=True, help="The HTML file to write.")
@click.option("--full", is_flag=True,
              help="Embed every figure as stored and draw every row (by default PNGs are "
                   "shrunk to 720 pixels, as 64-colour PNG or WebP, a figure that looks the "
                   "same as its twin's in another experiment is named instead of drawn again, "
                   "and tables are cut to 30 rows: the page of the shipped results stays under "
                   "3 MB).")
def report_page(results, out, full) -> None:
    """Write one self-contained HTML page of the stored results: the headline claims and a
    summary of every experiment by chapter (its claims, with the failures the printed
    values contradict told apart, printed cells and health, and a legend) at the top, then
    its tables beside the printed values (failing claims in red; filter and sort in the
    page), its figures with captions, the deviations its config cites, seeds and
    versions."""
    from estim.report import html as html_report

    where = project.locate()
    results = results or where.results
    pages = sorted((where.root / "docs" / "deviations").glob("*.md")) if where.root else []
    store.output_file(out, "--out")
    store.ensure_writable(out.parent)               # before the page is built, not after
    text_ = "\n".join(page.read_text() for page in pages if page.is_file())
    sections = html_report.sections(results, text_, where.config_dir, ANALYSES)
    if not sections:
        fail(f"no stored results under {results}/ (run 'estim reproduce')")
    page = html_report.page("estim: stored results", sections, full=full)
    try:
        store.atomic_write_bytes(out, page.encode("utf-8"))
    except OSError as exc:
        fail(f"cannot write {out} ({exc.strerror or exc})")
    click.echo(f"report: {len(sections)} experiments -> {out}")


@click.command()
@click.option("--results", type=click.Path(file_okay=False, path_type=Path),
              help="Folder of stored results [default: the project's results/].")
@click.option("--readme", type=click.Path(dir_okay=False, path_type=Path),
              help="Re-generate the summary blocks (<!-- summary: NAME --> ... "
                   "<!-- /summary -->) of this Markdown file in place.")
@click.option("--check", "check_only", is_flag=True,
              help="With --readme: write nothing; exit 1 naming the blocks that do not "
                   "match the stored tables.")
@click.option("--json", "as_json", is_flag=True,
              help="The same as data: per experiment, each claim's verdict counts (family "
                   "and per cell), fragile cells and ratio range, and the quoted ranges.")
def summary(results, readme, check_only, as_json) -> None:
    """Print each stored experiment's claims (holds / fails / undecided out of its cells,
    with the range of the ratio) and the ranges of the quantities its analysis quotes."""
    from estim.report import summary as summaries

    if check_only and readme is None:
        fail("--check applies only with --readme (it checks that file's generated blocks)")
    if as_json and readme is not None:
        fail("--json and --readme are two outputs; give one")
    results = results or project.locate().results
    if as_json:
        import json

        data = summaries.as_data(Path(results), ANALYSES)
        if not data:
            fail(f"no stored results under {results}/ (run 'estim reproduce')")
        click.echo(json.dumps(data, indent=1, allow_nan=False, default=str))
        return
    if readme is None:
        found = summaries.everything(results, ANALYSES)
        if not found:
            fail(f"no stored results under {results}/ (run 'estim reproduce')")
        output.markdown("\n\n".join("\n".join(lines) for lines in found.values()))
        return
    store.output_file(readme, "--readme")
    if not readme.is_file():
        fail(f"--readme {readme}: no such file")
    if readme.stat().st_size > MAX_README_BYTES:
        fail(f"--readme {readme}: larger than {MAX_README_BYTES >> 20} MB, not a README")
    try:
        text_ = readme.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise UsageError(f"{readme}: cannot read ({exc})") from None
    new, stale = summaries.refresh(text_, results, ANALYSES)
    if check_only:
        if stale:
            click.echo(f"{readme}: stale summary blocks: {', '.join(stale)} (re-generate with "
                       f"'estim summary --readme {readme}')")
            sys.exit(1)
        click.echo(f"{readme}: every summary block matches {results}/")
        return
    if stale:
        try:
            store.atomic_write_bytes(readme, new.encode())
        except OSError as exc:
            fail(f"cannot write {readme} ({exc.strerror or exc})")
    click.echo(f"{readme}: {len(stale)} block(s) re-generated" + (
        f" ({', '.join(stale)})" if stale else ""))


@click.command()
@click.argument("name", required=False)
@click.option("--out", type=NamedPath(dir_okay=False, path_type=Path),
              help="Write the listing to this Markdown file (docs/settings.md) instead.")
@click.option("--plugin", "plugins", multiple=True, type=NamedPath(dir_okay=False,
              path_type=Path), help="A Python file of models or estimators, as a config's "
              "plugins: names it, imported first so that its classes are listed too "
              "(repeatable).")
def settings(name, out, plugins) -> None:
    """List every setting a config can give, from its one declaration: each analysis' keys,
    each estimator's settings and each model's parameters, with type, default, unit and
    meaning (NAME: one analysis, estimator or model, built in or from a --plugin file; or a
    config file: its model's states, in the order a vector Q, P0 or x0 follows, and its
    parameters' values)."""
    from estim.config import listing as declared
    from estim.errors import ConfigError

    modules = []
    for plugin in plugins:
        try:
            modules += config.load_plugins([plugin.name], str(plugin))
        except ConfigError as exc:
            fail(f"--plugin {plugin}: {exc.message}")
    if name is not None and name.endswith((".yaml", ".yml")) and out is None:
        output.markdown(model_listing(Path(name)))
        return
    text_ = declared.listing(name, modules)
    if name is not None and text_.strip() == "":
        fail(f"no analysis, estimator or model named {name!r}")
    if out is None:
        output.markdown(text_)
        return
    header = ("# Settings\n\nEvery setting a config can give, generated by `estim settings "
              "--out docs/settings.md` from the declarations in the code (`tests/test_settings"
              ".py` fails when this file is stale).\n\n")
    try:
        store.atomic_write_bytes(out, (header + text_).encode())
    except OSError as exc:
        fail(f"cannot write {out} ({exc.strerror or exc})")
    click.echo(f"settings -> {out}", err=True)


def model_listing(path: Path) -> str:
    """``estim settings CONFIG``: the model of a config as the config makes it, its states in
    the order a vector ``Q``, ``P0`` or ``x0`` follows, and its parameters' values."""
    from estim.config.registry import MODELS

    exp = config.load_files([path], plan=False)[0]
    block = exp.spec.get("model")
    if not isinstance(block, dict) or block.get("name") not in MODELS:
        fail(f"{path}: estim settings CONFIG lists the model a config makes; this one "
             f"({exp.analysis}) has no model block")
    cls = MODELS[block["name"]]
    model = cls(block.get("variant"), **(block.get("params") or {}))
    made = (f" (from {block['netlist']}, input {block['input']}, output {block['output']})"
            if block.get("netlist") else "")
    lines = [f"### model `{cls.name}`{made}", "",
             "States, in the order of a vector Q, P0 or x0: "
             + ", ".join(f"`{s}`" for s in model.state_names), "",
             "| parameter | value in this config |", "|---|---|"]
    lines += [f"| {k} | {v!r} |" for k, v in vars(model.params).items()]
    if block.get("netlist"):
        from estim.spice.parameter_states import estimable

        lines += ["", "Values that may be estimated as states (the config's `estimate`): "
                  + ", ".join(f"`{n}`" for n in estimable(model))]
    return "\n".join(lines) + "\n"
