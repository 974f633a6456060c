"""Exudyn multibody plants of the linear and rotary delta."""
