"""A table of load cases solved and written as it goes: what `diffsusp simulate` calls, so that
the command line only parses and formats (DESIGN.md "Architecture": a thin edge).

`simulate_table(mech, table, out)` solves the static equilibrium of every row of a load table
(`diffsusp.io.loads_from_table`), `CHUNK` cases at a time (`diffsusp.statics.
solve_statics_chunks`), and appends each chunk's results rows (`diffsusp.io.results_table`) to
`out` as it completes. An interruption (KeyboardInterrupt, or the SIGTERM a caller turns into
one) stops the solve: the cases not solved are written with status -1 and NaN outputs, and the
returned `TableRun` says so. Units: those of the model (mm, N, rad).
"""

import dataclasses
import os
import types
from collections.abc import Callable

import numpy as np

from .errors import InputError, ModelFileError
from .io import ModelFile, loads_from_table, read_table, results_table
from .io.tables import Table, TableWriter
from .statics import (
    STATUS_TEXT,
    Status,
    bushing_states,
    flagged_cases,
    solve_statics_chunks,
    spring_states,
)

__all__ = ["CHUNK", "TableRun", "load_cases", "simulate_table"]

CHUNK = 256
"""Cases per solve (the last chunk is padded so that every chunk reuses one compiled shape)."""


def load_cases(model_file: ModelFile, loads) -> Table:
    """The load table `loads` names: a load table of the model file (when no file of that name
    exists) or a .csv / .parquet file (`diffsusp.io.read_table`).

    **Raises:** `ModelFileError` when it is neither; `InputError` for a table without rows.
    """
    text = os.fspath(loads)
    if text in model_file.load_tables and not os.path.exists(text):
        table = model_file.load_tables[text]
    elif not os.path.exists(text):
        known = ", ".join(model_file.load_tables) or "none"
        raise ModelFileError(
            f"no such file, and not a load table of the model (its tables: {known}); give a "
            ".csv or .parquet load table.", path=text)
    else:
        table = read_table(text)
    if table.n_rows == 0:
        raise InputError(f"{text}: the load table has no rows; give one row per load case.")
    return table


@dataclasses.dataclass
class TableRun:
    """What `simulate_table` did: per case its status (-1: not solved), `stable` and `law_valid`
    flags (False when not solved), residual and constraint error (NaN when not solved); the
    number of result columns written, the cases solved (`done`, the first ones) and the
    interruption that stopped the run (None when it ran to the end)."""

    status: np.ndarray
    stable: np.ndarray
    law_valid: np.ndarray
    residual: np.ndarray
    constraint_error: np.ndarray
    columns: int = 0
    done: int = 0
    interrupted: BaseException | None = None

    @classmethod
    def empty(cls, n: int) -> "TableRun":
        """A run of `n` cases none of which is solved yet."""
        nan = np.full(n, np.nan)
        return cls(status=np.full(n, int(Status.NOT_SOLVED), dtype=int), stable=np.zeros(n, bool),
                   law_valid=np.zeros(n, bool), residual=nan, constraint_error=nan.copy())

    def record(self, start: int, stop: int, sol) -> None:
        """Keep the status, flags and residuals of the solved cases `start:stop`."""
        for name in ("status", "stable", "law_valid", "residual", "constraint_error"):
            getattr(self, name)[start:stop] = np.asarray(getattr(sol, name))
        self.done = stop

    def summary(self) -> dict:
        """Counts and case lists (JSON-ready): cases, converged, not_solved, failed (case, status
        text, residual), unstable and law_invalid (`diffsusp.statics.flagged_cases`),
        max_residual, max_constraint_error (over the solved cases), columns, interrupted."""
        flags = flagged_cases(self)
        finite = self.residual[np.isfinite(self.residual)]
        return dict(
            cases=int(self.status.size),
            converged=int(np.sum(self.status == Status.CONVERGED)),
            not_solved=int(np.sum(self.status == Status.NOT_SOLVED)),
            failed=[dict(case=int(c), status=STATUS_TEXT.get(int(self.status[c]),
                                                               str(self.status[c])),
                         residual=float(self.residual[c])) for c in flags["failed"]],
            unstable=flags["unstable"].tolist(),
            law_invalid=flags["law_invalid"].tolist(),
            max_residual=float(np.max(finite, initial=0.0)),
            max_constraint_error=float(np.nanmax(self.constraint_error, initial=0.0)),
            columns=self.columns,
            interrupted=self.interrupted is not None,
        )


def simulate_table(mech, table: Table, out, *, max_steps: int = 50,
                   progress: Callable[[int], None] | None = None) -> TableRun:
    """Solve every row of the load table `table` on `mech` and write one results row per case
    to `out` (.csv or .parquet, `diffsusp.io.tables.TableWriter`) as its chunk completes.

    **Arguments:** `max_steps`: Newton iterations per case; `progress`: called with the number
    of cases done after each chunk.

    **Returns:** a `TableRun`. An interruption (KeyboardInterrupt or a subclass) is not
    raised: the rows of the cases not solved are written (status -1, their loads, NaN
    outputs) and the run's `interrupted` holds it.
    """
    loads = loads_from_table(mech, table)
    n = loads.n_cases
    run = TableRun.empty(n)
    writer = None

    def write(res):
        nonlocal writer
        if writer is None:
            writer = TableWriter(out, res.names, res.units)
            run.columns = len(res.names)
        writer.append(dict(res.columns))

    try:
        for start, stop, sol in solve_statics_chunks(mech, loads, CHUNK, max_steps=max_steps,
                                                     throw=False):
            write(_results(mech, sol, table, start, stop))
            run.record(start, stop, sol)
            if progress is not None:
                progress(stop)
    except KeyboardInterrupt as e:
        run.interrupted = e
    finally:
        if run.done < n:  # the rest: their loads and status -1, every output NaN
            write(_results(mech, _unsolved(mech, n - run.done), table, run.done, n,
                           solved=False))
        if writer is not None:
            writer.close()
    return run


def _results(mech, sol, table: Table, start: int, stop: int, *, solved: bool = True) -> Table:
    """The results rows of cases `start:stop`, their load columns from `table` (`solved=False`:
    the stand-in of cases not solved)."""
    part = Table(columns={k: v[start:stop] for k, v in table.columns.items()},
                 units=dict(table.units))
    if solved:
        bushings = bushing_states(mech, sol.q) if mech.bushings.names else None
        springs = spring_states(mech, sol.q) if mech.springs.names else None
    else:  # NaN element states, no program to compile
        k, n_b, n_s = stop - start, len(mech.bushings.names), len(mech.springs.names)
        bushings, springs = [np.full((k, n_b, 3), np.nan)] * 4, [np.full((k, n_s), np.nan)] * 2
    return results_table(mech, sol, part, first_case=start, bushings=bushings, springs=springs)


def _unsolved(mech, n: int):
    """A stand-in solution for cases not solved: NaN outputs, status -1, flags 0."""
    nan = np.full(n, np.nan)
    return types.SimpleNamespace(
        q=np.full((n, 6 * len(mech.parts)), np.nan), status=np.full(n, int(Status.NOT_SOLVED)),
        iterations=np.zeros(n), residual=nan, constraint_error=nan, stable=np.zeros(n, bool),
        law_valid=np.zeros(n, bool))
