"""Thin pythonfmu adapters: FMI variables in, calls into delta/ and multibody/, FMI variables out."""
