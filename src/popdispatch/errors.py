"""Exceptions raised by popdispatch. Each message is one line and names the offending element."""


class PopdispatchError(Exception):
    """Base class of every error popdispatch raises on purpose."""


class FeederError(PopdispatchError, ValueError):
    """The feeder is not a valid radial network (meshed, disconnected, bad element)."""


class MeshedError(FeederError):
    """The network has a loop: ``loop_lines`` names its lines (the feeder's line names), the
    first of them the one that closes it."""

    def __init__(self, message: str, loop_lines: list[str] | None = None):
        super().__init__(message)
        self.loop_lines = list(loop_lines or [])


class FleetError(PopdispatchError, ValueError):
    """A generator table is invalid (unknown bus, bad cost or limit)."""


class ProfileError(PopdispatchError, ValueError):
    """Load profiles are missing, malformed or inconsistent with the feeder."""


class InfeasibleError(PopdispatchError):
    """The dispatch problem has no feasible solution (demand, limits or capacity)."""


class OptionError(PopdispatchError, ValueError):
    """A run option is malformed or names something the problem lacks (bad usage: the CLI exits
    with code 2). ``option`` names the option, e.g. ``"--event"``."""

    def __init__(self, message: str, option: str | None = None):
        super().__init__(message)
        self.option = option
