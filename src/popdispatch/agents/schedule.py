"""The population dynamics' round: which agent acts at which tick of a revision round (the
generic clock: :mod:`popdispatch.agents.clock`).

One round is one Euler step of the mean dynamics (``h`` seconds of the dynamics' time,
integrate/steppers.py): measure the lines, price them, compare fitness with the neighbours,
move mass in pairwise transactions. Agents act on whole ticks of the clock; a message takes
half a tick (plus any simulated delay), so what is sent at one tick is in the receiver's
inbox at the next.

======  ==========  ===================================================================
tick    who         what
======  ==========  ===================================================================
0       plant       measures the limited lines' flows, sends them to both end controllers
1       controllers the mode's signal law on the latest measurement, sent to their side
2       DGs         fitness from own output and the latest signals; status to neighbours
3       DGs         pairwise flows and the flux limiter from the latest statuses; offers
4       DGs         accept this round's offers, scaled by the receiver's limiter
5       DGs         commit the accepted offers (abort the others); resend open decisions
======  ==========  ===================================================================
"""

from __future__ import annotations

from enum import IntEnum


class Phase(IntEnum):
    """The ticks of a round (see the module docstring)."""

    MEASURE = 0
    SIGNAL = 1
    STATUS = 2
    OFFER = 3
    ACCEPT = 4
    COMMIT = 5


#: Ticks (simulated seconds) per round.
TICKS_PER_ROUND = len(Phase)
