"""The ``popdispatch`` command line (click); see :mod:`popdispatch.cli.process` for exit codes and
errors, :mod:`popdispatch.cli.clock` for times, :mod:`popdispatch.cli.commands` for the commands.

Importing this package imports only click and the standard library (and popdispatch's light
modules): numpy, pandas, numba, pandapower, scipy and matplotlib are imported by the commands
that use them, so ``--help`` and usage errors are quick.
"""

from popdispatch.cli.agents import agents
from popdispatch.cli.clock import (
    EXIT_INTERRUPTED,
    EXIT_PROBLEM,
    EXIT_USAGE,
    Failure,
    command_seconds,
    process_age_seconds,
    stamp,
)
from popdispatch.cli.commands import cli
from popdispatch.cli.compare import compare
from popdispatch.cli.cosim import cosim
from popdispatch.cli.process import main
from popdispatch.cli.sweep import sweep, sweep_report
from popdispatch.constants import MINUTES_PER_DAY
from popdispatch.report.text import infeasible_day_message, infeasible_minute_message

for _command in (sweep, sweep_report, agents, compare, cosim):
    cli.add_command(_command)

__all__ = [
    "EXIT_INTERRUPTED",
    "EXIT_PROBLEM",
    "EXIT_USAGE",
    "MINUTES_PER_DAY",
    "Failure",
    "cli",
    "command_seconds",
    "infeasible_day_message",
    "infeasible_minute_message",
    "main",
    "process_age_seconds",
    "stamp",
]
