"""Annex G of the tyre thesis as data: the identified polynomial models and lateral compliances.

spec: tyre §4.7 (Annex G), §4.5 (Tables 10, 11), §0.4, §0.5.9–10, CORRECTIONS 5, 10. Units of
the thesis (spec §0.3): F_z in kN, δ′ in m, φ′ and γ in rad, F_y in N, M_z in N·m.

`data/annex_g.csv` holds **every printed cell** of Tables 34–57 (2 638 rows, 348 identified
values), one row each:
table, tyre, pressure [bar], output (Fy | Mz), block, i, j, the printed text, value, σ %,
status and a note with the seed line. The blocks and their indices (b_{F,X,i,j}: i the power of
the input, j the power of F_z [kN]):

- `delta` (δ′, i = 1…7, j = 1…3), `phi` (φ′, i = 1…7, j = 1…3), `gamma` (γ, i = 1…5,
  j = 0…3), `one` (the offset, i = 1, j = 0…3), `P2` (M_z only: the −F_y·F_x coupling, one cell
  at j = 0), `Ly` (the relaxation term, row k = 0…6: the column is (Ḟ_y/ω)·(k+1)·δ′^k·F_z^j of
  (G-8)/(G-17), so the printed row is the power of δ′ in the derivative, i − 1).

Status of a cell: `value` (identified, non-zero), `zero` (printed "0 (0%)": not identifiable or
not significant, removed by the algorithm), `forced` (printed "*": set to 0 by the author so
the behaviour matches the expected shape), `absent` (printed "/": not in the initial model),
`missing` (a row the seed's text extraction lost, read as 0). Decisions, each noted in the
cell's `note`:

- **Table 48** prints its Ly rows 1…6; they are read as k = 0…5 (spec §0.5.10: the first row is
  the constant part of the relaxation, as in every other table: 0.006105·F_z + 0.00012·F_z³
  against Table 47's 0.007545·F_z + 0.0001618·F_z³); its k = 6 row is `missing`.
- **Table 41**: the Ly row k = 5 is absent from the seed's text (all the other cells of that
  block are 0): `missing`.
- **Table 55**: b_{Mz,δ′,1,3} is printed "99" with no sign; the value is −99 (CORRECTIONS 5).
- The "1" (offset) rows are labelled "l" or "λ" by the OCR; the M_z "Ly" row "lγ" (Table 48):
  blocks are read by position, which is fixed by (G-3…G-8) and (G-11…G-17).

G.2 (the lateral compliances K_y⁻¹ [m/N] identified on F_y by (G-20) and on M_z by (G-23))
is `COMPLIANCE`; Table 11 (their inverses as printed, N/m) is `TABLE_11`.
"""

import csv
import dataclasses
import functools
import math
from pathlib import Path

from ..errors import InputError
from .thesis_sets import PRESSURES, TYRES

__all__ = ["Cell", "cells", "table", "table_number", "coefficients", "COMPLIANCE",
           "COMPLIANCE_SIGMA_PCT", "TABLE_11", "lateral_stiffness", "relaxation_length",
           "R_ROLLING"]

PATH = Path(__file__).parent / "data" / "annex_g.csv"
BLOCKS = ("delta", "phi", "gamma", "one", "P2", "Ly")
R_ROLLING = 0.294
"""The rolling radius the thesis implies, 18 mm ↔ 3.5° (spec §0.3 (c)) [m]."""


@dataclasses.dataclass(frozen=True)
class Cell:
    """One printed cell of an Annex G table (see the module docstring)."""

    table: int
    tyre: str
    pressure: float
    output: str
    block: str
    i: int
    j: int
    printed: str
    value: float  # nan for "/" cells
    sigma_pct: float  # nan where none is printed
    status: str
    note: str

    @property
    def name(self) -> str:
        """The parameter name used by `diffsusp.tyre.poly`: `b_<output>_<block>_<i>_<j>`."""
        return f"b_{self.output}_{self.block}_{self.i}_{self.j}"


@functools.cache
def cells() -> tuple[Cell, ...]:
    """Every cell of Tables 34–57."""
    out = []
    with PATH.open(newline="") as f:
        for r in csv.DictReader(f):
            out.append(Cell(int(r["table"]), r["tyre"], float(r["pressure_bar"]), r["output"],
                            r["block"], int(r["i"]), int(r["j"]), r["printed"],
                            float(r["value"]) if r["value"] else math.nan,
                            float(r["sigma_pct"]) if r["sigma_pct"] else math.nan,
                            r["status"], r["note"]))
    return tuple(out)


def table_number(tyre: str, pressure: float, output: str) -> int:
    """34 + 12·(M_z) + 3·tyre + pressure index (Tables 34–45 F_y, 46–57 M_z)."""
    if tyre not in TYRES:
        raise InputError(f"unknown tyre {tyre!r}; Annex G has {TYRES}")
    if pressure not in PRESSURES:
        raise InputError(f"pressure {pressure!r} bar: Annex G has {PRESSURES}")
    if output not in ("Fy", "Mz"):
        raise InputError(f"output {output!r}: 'Fy' or 'Mz'")
    return 34 + 12 * (output == "Mz") + 3 * TYRES.index(tyre) + PRESSURES.index(pressure)


def table(number: int) -> tuple[Cell, ...]:
    """The cells of one table (34–57)."""
    if not 34 <= number <= 57:
        raise InputError(f"Annex G has Tables 34–57; got {number}")
    return tuple(c for c in cells() if c.table == number)


def coefficients(tyre: str, pressure: float, output: str, *, include_ly: bool = True,
                 include_p2: bool = True) -> dict[str, float]:
    """The non-zero coefficients of one table by name (b_Fy_delta_5_2, b_Fy_Ly_0_1, ...)."""
    n = table_number(tyre, pressure, output)
    skip = set() if include_ly else {"Ly"}
    if not include_p2:
        skip.add("P2")
    return {c.name: c.value for c in table(n) if c.status == "value" and c.block not in skip}


# G.2: K_y⁻¹ [m/N] with σ %, identified on F_y (G.2.1, model G-20) and on M_z (G.2.2, G-23).
COMPLIANCE = {
    "Fy": {"dunlop_r16": (6.354e-6, 5.44e-6, 4.515e-6),
           "michelin_r15": (6.841e-6, 5.897e-6, 4.826e-6),
           "michelin_r16": (7.743e-6, 6.702e-6, 5.523e-6),
           "michelin_r17": (6.541e-6, 5.564e-6, 4.427e-6)},
    "Mz": {"dunlop_r16": (5.831e-6, 5.721e-6, 5.316e-6),
           "michelin_r15": (5.741e-6, 5.311e-6, 5.222e-6),
           "michelin_r16": (5.845e-6, 5.767e-6, 5.314e-6),
           "michelin_r17": (6.437e-6, 5.924e-6, 5.643e-6)},
}
COMPLIANCE_SIGMA_PCT = {
    "Fy": {"dunlop_r16": (0.1, 0.091, 0.13), "michelin_r15": (0.079, 0.079, 0.12),
           "michelin_r16": (0.073, 0.076, 0.12), "michelin_r17": (0.087, 0.094, 0.1)},
    "Mz": {"dunlop_r16": (0.23, 0.23, 0.26), "michelin_r15": (0.22, 0.25, 0.27),
           "michelin_r16": (0.32, 0.31, 0.37), "michelin_r17": (0.2, 0.22, 0.25)},
}
# Table 11: K_y [N/m] on F_y and on M_z as printed (run "a" for the Michelin R17).
TABLE_11 = {
    "Fy": {"dunlop_r16": (157375, 183822, 221495), "michelin_r15": (146167, 169578, 207194),
           "michelin_r16": (129154, 149214, 181062), "michelin_r17": (152890, 179716, 225878)},
    "Mz": {"dunlop_r16": (171510, 174808, 188112), "michelin_r15": (174175, 188278, 191483),
           "michelin_r16": (171072, 173386, 188190), "michelin_r17": (155340, 168818, 177213)},
}


def lateral_stiffness(tyre: str, pressure: float, output: str = "Fy") -> float:
    """K_y = 1/(G.2 compliance) [N/m], identified on `output` (spec §8 item 2)."""
    table_number(tyre, pressure, output)
    return 1.0 / COMPLIANCE[output][tyre][PRESSURES.index(pressure)]


def relaxation_length(tyre: str, pressure: float, fz: float = 4.5, *,
                      rolling_radius: float = R_ROLLING) -> float:
    """σ = R_r·|L_Fy(δ′ = 0, F_z)| [m] from the F_y table's Ly row k = 0 (spec §3.4, §8 item 8):
    L_Fy = (∂Fy_pneu/∂δ′)/K_y, dimensionless, = Σ_j b_{Fy,Ly,0,j}·F_z^j at δ′ = 0; F_z [kN]."""
    b = coefficients(tyre, pressure, "Fy")
    L = sum(v * fz**int(k.rsplit("_", 1)[1]) for k, v in b.items()
            if k.startswith("b_Fy_Ly_0_"))
    return rolling_radius * abs(L)
