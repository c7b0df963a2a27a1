"""Dispatch modes: how node controllers turn line flows into fitness signals.

- ``paper`` (:mod:`popdispatch.modes.paper`): the paper's barrier and overflow signal.
- ``exact`` (:mod:`popdispatch.modes.exact`): capacity-constrained revision and integrating
  line prices; its equilibria are the KKT points of the DC-OPF.
- ``voltage`` (:mod:`popdispatch.modes.voltage`): exact mode plus voltage prices at the
  monitored buses (LinDistFlow); its equilibria are the KKT points of the LinDistFlow OPF.

Each mode is a payoff mechanism (:class:`Mode`, :mod:`popdispatch.modes.mechanism`) in its own
module: the compiled payoff kernel ``payoff`` and the mode's record ``MODE`` with its
defaults. All modes take the same arguments
(:class:`~popdispatch.game.parameters.GameParameters`, one minute's
:class:`~popdispatch.game.parameters.MinuteInputs`), so the integrator and the dynamics never
depend on the mode.

Adding a mode: a module here with its compiled ``payoff``, its ``MODE`` record and a
:class:`~popdispatch.modes.mechanism.ModeTag` subclass carrying the kernel (``kernel =
staticmethod(payoff)``); a :class:`ModeCode` member; its entry in :data:`MODES` and in
:data:`TAGS`. The tag's class picks the kernel when numba compiles: a static dispatch that
numba caches on disk (a kernel taking a function argument recompiles in every process) and
that compiles a run's own mode only. Nothing outside this package changes.
"""

from __future__ import annotations

from popdispatch.game.parameters import PriceLaw
from popdispatch.modes import exact, paper, voltage
from popdispatch.modes.mechanism import Mode, ModeCode, ModeTag

MODES = {mode.name: mode for mode in (paper.MODE, exact.MODE, voltage.MODE)}

#: Each mode's tag classes by price law (the plain law's for a law the mode does not know).
TAGS: dict[ModeCode, dict[PriceLaw, type]] = {
    ModeCode.PAPER: {PriceLaw.PLAIN: paper.PaperTag},
    ModeCode.EXACT: {PriceLaw.PLAIN: exact.ExactTag, PriceLaw.TREE: exact.ExactTreeTag,
                     PriceLaw.SCALED: exact.ExactScaledTag},
    ModeCode.VOLTAGE: {PriceLaw.PLAIN: voltage.VoltageTag, PriceLaw.TREE: voltage.VoltageTreeTag},
}  # fmt: skip


#: Exact mode's tag classes with the pinned lines' and pairs' prices hastened, by price law
#: (modes/exact.py ``hasten_pinned``): the engine's kernels with adaptive steps on a radial
#: feeder with limited lines.
PINNED_TAGS: dict[PriceLaw, type] = {PriceLaw.PLAIN: exact.ExactPinnedTag,
                                     PriceLaw.TREE: exact.ExactTreePinnedTag,
                                     PriceLaw.SCALED: exact.ExactScaledPinnedTag}  # fmt: skip

#: Each mode's tag class on a meshed network (the plain law only: the tree and scaled laws
#: read the tree of limited lines).
MESH_TAGS: dict[ModeCode, type] = {ModeCode.PAPER: paper.PaperMeshTag,
                                   ModeCode.EXACT: exact.ExactMeshTag}  # fmt: skip


def mode_tag(code: ModeCode, price_law: PriceLaw = PriceLaw.PLAIN, meshed: bool = False,
             pinned: bool = False) -> ModeTag:  # fmt: skip
    """The compile-time record of the mode ``code`` with exact mode's line-price law (a
    choice of kernel, so a run compiles only its own law; paper mode has no line prices).
    ``pinned``: exact mode's kernel that hastens the pinned lines' prices, where its law has
    one (:data:`PINNED_TAGS`).
    The scaled law exists for exact mode only: voltage mode with it raises
    :class:`~popdispatch.errors.OptionError`. ``meshed``: the kernel of a meshed network
    (distribution factors, :mod:`popdispatch.game.mesh`), paper or exact mode with the plain
    law; another law or voltage mode raises :class:`~popdispatch.errors.OptionError`."""
    law, code = PriceLaw(price_law), ModeCode(code)
    if meshed:
        from popdispatch.errors import OptionError

        if code not in MESH_TAGS:
            raise OptionError(f"{code.name.lower()} mode runs on radial feeders only (a meshed "
                              "network: paper or exact mode)", "--mode")  # fmt: skip
        if law != PriceLaw.PLAIN and code == ModeCode.EXACT:
            raise OptionError(f"the {law.name.lower()} price law reads the tree of a radial "
                              "feeder (a meshed network: plain)", "--price-law")  # fmt: skip
        return MESH_TAGS[code](int(code))
    if law == PriceLaw.SCALED and code == ModeCode.VOLTAGE:
        from popdispatch.errors import OptionError

        raise OptionError("the scaled price law is for exact mode only (voltage mode: plain or "
                          "tree)", "--price-law")  # fmt: skip
    if pinned and code == ModeCode.EXACT and law in PINNED_TAGS:
        return PINNED_TAGS[law](int(code))
    tags = TAGS[code]
    return tags.get(law, tags[PriceLaw.PLAIN])(int(code))


def get_mode(name: str) -> Mode:
    try:
        return MODES[name]
    except KeyError:
        raise ValueError(f"unknown mode {name!r} (known: {', '.join(MODES)})") from None


__all__ = ["MESH_TAGS", "MODES", "PINNED_TAGS", "TAGS", "Mode", "ModeCode", "ModeTag", "get_mode",
           "mode_tag"]
