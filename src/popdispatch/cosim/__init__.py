"""popdispatch in a mosaik 3 co-simulation (docs/cosim.md): the dispatcher (DG agents and node
controllers on the online engine) as a mosaik simulator reading measured line flows and the
loads' demand and writing the DGs' set points; a pandapower plant (AC power flow); load
profiles; a CSV recorder; and the ELV scenario (:func:`~popdispatch.cosim.scenario.run_cosim`).

mosaik (``pip install "popdispatch[cosim]"``) is imported by the simulators' modules only.
"""
