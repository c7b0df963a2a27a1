"""The source bus as a counterparty: it carries at once what the generators stop supplying
(a DG trip) and hands it back to them in the same pairwise transactions.

Physically the source bus (the feeder head) balances the feeder at every instant: when a DG
trips, its output is imported at once. The source bus's controller is the agent that measures
that import and so the only one that sees the step. It holds the step as its *committed
position* (MW): the committed state of the feeder is then the generators' set points, the
transactions in flight and this position, and it balances exactly at every instant
(:meth:`popdispatch.agents.population.AgentSystem.committed_imbalance_mw`). Every round it offers
its position to the live generators in equal parts (offer, accept, commit, as between two
generators: :mod:`popdispatch.agents.generator`); each accepts what its room allows, and the
position decays to zero as long as the others have the room. The generators' own dynamics
then move the taken-over power to where it is cheapest (the DC-OPF without the tripped DG).
"""

from __future__ import annotations

from popdispatch.agents.generator import GeneratorAgent
from popdispatch.agents.messages import Offer
from popdispatch.agents.schedule import Phase

#: Agent id of the source bus's controller.
SOURCE_ID = "source"


class SourceAgent(GeneratorAgent):
    """The source bus's controller (module docstring). ``generators``: ids of the generators
    it can hand power to; the position starts at 0 (no step yet)."""

    PHASES = (Phase.OFFER, Phase.COMMIT)

    def __init__(self, generators: list[str], timeout: int = 1, copies: int = 1, network=None):
        super().__init__(None, -1, None, list(generators), timeout, 0, copies, False, network)
        self.position_mw = 0.0

    @property
    def p(self) -> float:
        """The source's committed position beyond the minute's own import, MW."""
        return self.position_mw

    def _set(self, p_mw: float) -> None:
        self.position_mw = p_mw

    def _offer(self, rnd: int) -> None:
        """Offer the position not yet offered to the live generators in equal parts."""
        if self.quiet or not self.neighbours:
            return
        offered = sum(amount for _, _, amount in self.open_offers.values())
        free = self.planned - offered
        if free <= 1e-12:
            return
        part = free / len(self.neighbours)
        for aid in self.neighbours:
            txid = f"{self.aid}/{rnd}/{aid}"
            self.open_offers[txid] = (aid, rnd, part)
            self.send(Offer(rnd, txid, part), aid)
