"""pythonfmu adapters for the delta components and the FMU builder."""
