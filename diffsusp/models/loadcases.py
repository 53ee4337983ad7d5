"""The thesis's K&C load-case tables and their mapping to `Loads`, defined beside K&C
(`diffsusp.kc.loadcases`) and published here with the built-in models they were written for."""

from ..kc.loadcases import TABLE_4_4, TABLE_5_1, thesis_load_cases

__all__ = ["TABLE_4_4", "TABLE_5_1", "thesis_load_cases"]
