"""``estim validate``: every check of a config without running it, loading only the
analysis the config names (no tables, no drawing)."""

from __future__ import annotations

import click

from estim.cli import arguments
from estim.cli.group import fail
from estim.cli.options import max_work_option
from estim.config import loading as config


@click.command()
@click.argument("configs", nargs=-1, required=True)
@max_work_option
def validate(configs, max_work) -> None:
    """Check CONFIGS without running them (overrides KEY.PATH=VALUE as for run)."""
    paths, overrides = arguments.split_arguments(configs)
    if not paths:
        fail("no config file given")
    for exp in config.load_files(paths, overrides, max_work=max_work):
        click.echo(f"{exp.source}: ok ({exp.name})")
