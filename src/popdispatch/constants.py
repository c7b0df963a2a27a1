"""Constants shared across popdispatch; importing this module imports nothing else (the CLI
uses it before numpy or pandas are loaded)."""

#: Minutes in a day: profiles and runs number minutes 1..MINUTES_PER_DAY.
MINUTES_PER_DAY = 1440
#: Kilowatts per megawatt: people give kW, the engine works in MW.
KW_PER_MW = 1000.0
