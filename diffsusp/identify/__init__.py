"""Identification of model parameters from measurements (spec stiffness ch. 4–5, geometry
ch. 2–3): `direct` (linear, from measured equilibria), with `iterative`, `least_squares` and
`sensitivity` alongside. Each takes a mechanism and measurements and returns the identified
mechanism and a report."""

from .direct import DirectReport, DirectSystem, direct, direct_system

__all__ = ["DirectReport", "DirectSystem", "direct", "direct_system"]
