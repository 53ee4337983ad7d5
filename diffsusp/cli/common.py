"""Shared pieces of the `diffsusp` command: the Typer app, consoles, exit codes, and turning the
library's errors into one-line messages with a distinct exit code."""

import contextlib
import json
import sys

import typer
from rich.console import Console

EXIT_OK = 0
EXIT_BAD_INPUT = 2
EXIT_NOT_CONVERGED = 3
EXIT_MODEL_ERROR = 4

app = typer.Typer(add_completion=False, no_args_is_help=True,
                  help="Differentiable K&C suspension solver (units: mm, N, deg at the edge).")


@app.callback()
def _main():
    """diffsusp: static equilibrium, K&C analysis and identification of suspension models."""


def enable_x64():
    """float64, and a persistent compilation cache so that the second run of a command does
    not compile again (`$DIFFSUSP_CACHE`, default `~/.cache/diffsusp/jax`; set it to an empty
    string to disable)."""
    import os

    import jax

    jax.config.update("jax_enable_x64", True)
    cache = os.environ.get("DIFFSUSP_CACHE", os.path.expanduser("~/.cache/diffsusp/jax"))
    if cache and not jax.config.jax_compilation_cache_dir:
        jax.config.update("jax_compilation_cache_dir", cache)
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)


def console(stderr: bool = False) -> Console:
    """A Rich console; 120 columns when not a terminal (logs, test runners)."""
    c = Console(stderr=stderr)
    if not c.is_terminal:
        c = Console(stderr=stderr, width=120)
    return c


def fail(message: str, code: int) -> typer.Exit:
    """Print `message` on stderr and return the Exit to raise."""
    console(stderr=True).print(f"[bold red]error:[/] {message}", highlight=False)
    return typer.Exit(code=code)


@contextlib.contextmanager
def cli_errors():
    """Map the library's exceptions to messages and exit codes (bad input 2, non-convergence 3,
    unsolvable model 4)."""
    from diffsusp.errors import ConvergenceError, ModelError

    try:
        yield
    except ConvergenceError as e:
        raise fail(str(e), EXIT_NOT_CONVERGED) from None
    except (FileNotFoundError, IsADirectoryError, PermissionError) as e:
        raise fail(f"cannot read {e.filename}: {e.strerror}", EXIT_BAD_INPUT) from None
    except ModelError as e:
        code = EXIT_BAD_INPUT if getattr(e, "bad_input", False) else EXIT_MODEL_ERROR
        raise fail(str(e), code) from None


def print_json(obj) -> None:
    """Machine-readable output on stdout (no Rich markup)."""
    sys.stdout.write(json.dumps(obj, indent=2, default=_jsonable) + "\n")


def _jsonable(x):
    import numpy as np

    if isinstance(x, np.ndarray | np.generic):
        return x.tolist()
    if hasattr(x, "__array__"):
        return np.asarray(x).tolist()
    raise TypeError(f"not JSON serialisable: {type(x).__name__}")
