"""Every error class of the project.

``EstimError`` is the root: the CLI turns a ``ConfigError`` (or ``UsageError``) into one line
and exit 2, anything else raised after a run started into one line and exit 3.
"""

from __future__ import annotations


class EstimError(Exception):
    """Root of estim's own errors."""


class ConfigError(EstimError, ValueError):
    """A config is malformed; the message is one line naming the file and key path."""

    def __init__(self, source: str, path: str, message: str) -> None:
        self.source, self.path, self.message = source, path, message
        where = f"{source}: {path}: " if path else f"{source}: "
        super().__init__(where + message)


class ConfigErrors(ConfigError):
    """Several problems in one config: the message holds one line per problem."""

    def __init__(self, errors: list[ConfigError]) -> None:
        self.errors = errors
        first = errors[0]
        super().__init__(first.source, first.path, first.message)
        self.args = ("\n".join(str(e) for e in errors),)

    def __str__(self) -> str:
        return self.args[0]


class UsageError(EstimError):
    """A command cannot do what was asked (a folder it may not write, a missing baseline)."""


class SettingError(EstimError, ValueError):
    """A setting's value cannot be used; ``key`` names the setting (its key path within its
    block: ``Q``, ``noise.levels[1]``), so a config error can point at it without parsing
    the message."""

    def __init__(self, key: str, reason: str) -> None:
        self.key, self.reason = key, reason
        super().__init__(f"{key}: {reason}")


class ParameterError(EstimError, ValueError):
    """A model parameter override names an unknown parameter or has a bad value."""


class SimulationError(EstimError, RuntimeError):
    """The stiff integration or the steady-state search failed."""


class ReferenceJoinError(EstimError, ValueError):
    """Our table and the reference table do not join one-to-one on the declared key."""


class Notice(UserWarning):
    """Something a user should know that is no error (a netlist's input waveform that the
    config's input replaces): ``warnings.warn(text, Notice)``; the command line prints it as
    one line ``notice: text`` on standard error."""
