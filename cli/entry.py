"""The ``estim`` entry point. It lists the commands without importing them, so ``estim
--help``, ``estim -V`` and shell completion of command names answer at once; the commands
(:mod:`estim.cli.main`, which loads numpy, scipy, pandas and matplotlib) load only to run one.

Shell completion (bash; zsh and fish alike with ``zsh_source``/``fish_source``)::

    eval "$(_ESTIM_COMPLETE=bash_source estim)"
"""

from __future__ import annotations

import importlib

import click

import estim
from estim.cli.group import Group, debug_option

SHORT_HELP = {
    "check": "Re-run configs and compare every cell with the stored tables.",
    "list": "Show the configs and the thesis tables each reproduces.",
    "report": "Write one self-contained HTML page of the stored results.",
    "merge": "Gather the cells of sharded runs and write the tables.",
    "reproduce": "Run every config of configs/ (the thesis tables on the default settings).",
    "run": "Run the experiment(s) of CONFIGS and write OUT/<config name>/.",
    "settings": "List every setting a config can give: analyses, estimators, models.",
    "spice": "Simulate CONFIG's netlist circuit in estim and in ngspice and compare.",
    "summary": "Print each experiment's claim verdicts and quoted ranges from RESULTS.",
    "table": "Print the METRIC tables of every experiment found under RESULTS.",
    "tune": "Fit the Q (and R) of one estimator of CONFIG by maximum likelihood.",
    "validate": "Check CONFIGS without running them.",
}
"""One line per command of :mod:`estim.cli.main` (a test keeps the two in step)."""

OWN_MODULE = {"list": ("estim.cli.listing", "list_configs"),
              "validate": ("estim.cli.validating", "validate"),
              "table": ("estim.cli.tabling", "table")}
"""Commands that load from a module of their own, without :mod:`estim.cli.main` and what it
imports: (module, name of the command)."""


class LazyGroup(Group):
    """A group whose commands live in :mod:`estim.cli.main` and load on first use."""

    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted(SHORT_HELP)

    def get_command(self, ctx: click.Context, name: str) -> click.Command | None:
        if name not in SHORT_HELP:
            return None
        if name in OWN_MODULE:
            module, attribute = OWN_MODULE[name]
            return getattr(importlib.import_module(module), attribute)
        return importlib.import_module("estim.cli.main").main.commands.get(name)

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        with formatter.section("Commands"):
            formatter.write_dl([(name, SHORT_HELP[name]) for name in self.list_commands(ctx)])

    def shell_complete(self, ctx: click.Context, incomplete: str) -> list:
        from click.shell_completion import CompletionItem

        items = [CompletionItem(name, help=text) for name, text in SHORT_HELP.items()
                 if name.startswith(incomplete)]
        return items + click.Command.shell_complete(self, ctx, incomplete)


@click.group(cls=LazyGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(estim.__version__, "-V", "--version", prog_name="estim")
@debug_option
def main(debug: bool) -> None:
    """Reproduce the result tables of Bansal (2019), state estimation in ODE/PDE models.

    Exit codes: 0 ok, 1 check found differences, 2 usage or config error, 3 a run failed,
    130 interrupted, 143 terminated.
    """
