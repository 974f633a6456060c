"""delta-cosim's co-simulation master. Rooms: fmi (FMU access), engine (plan, algorithms, execution), observers,
io, analysis; run.py composes a run; api.py and cli.py on top (see docs/layout.md)."""
