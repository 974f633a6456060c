"""The co-simulation master: scenarios, FMU access, algorithms, observers, CLI."""
