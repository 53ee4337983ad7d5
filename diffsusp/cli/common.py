"""Shared pieces of the `diffsusp` command: the Typer app, consoles, exit codes, and turning the
library's errors into one-line messages with a distinct exit code.

Exit codes (every verb): 0 success, 1 an internal error (a bug: please report it), 2 bad input
(paths, files, tables, arguments, an output that cannot be written), 3 a load case or a fit did
not converge, 4 a model that cannot be solved as given, 130 interrupted (SIGINT or SIGTERM;
the cases finished so far are on disk).

Everything a library message or a path holds is printed verbatim: Rich markup is used only for
the `error:` and `warning:` labels, never for text that comes from a file, a name or an argument.
"""

import contextlib
import enum
import errno
import json
import os
import signal
import sys
import warnings
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console
from rich.markup import escape
from rich.text import Text
from typer.exceptions import TyperException

EXIT_OK = 0
EXIT_INTERNAL = 1
EXIT_BAD_INPUT = 2
EXIT_NOT_CONVERGED = 3
EXIT_MODEL_ERROR = 4
EXIT_INTERRUPTED = 130

class _App(typer.Typer):
    """The console entry point (`diffsusp = diffsusp.cli:app`). An interrupted run (exit 130,
    SIGINT or SIGTERM) ends with `os._exit` once its message is printed and what it finished is
    written: JAX abandons a compilation that a signal interrupts, but XLA's
    threads carry on, and the interpreter's normal shutdown waited for them (the rest of the
    compile: ~10 min on 10⁶ rows) and then crashed (SIGSEGV). Typer's test runner calls the
    click command, not this, so tests keep their process."""

    def __call__(self, *args, **kwargs):
        try:
            return super().__call__(*args, **kwargs)
        except SystemExit as e:
            if e.code == EXIT_INTERRUPTED:
                for stream in (sys.stdout, sys.stderr):
                    try:
                        stream.flush()
                    except (OSError, ValueError):
                        pass
                os._exit(EXIT_INTERRUPTED)
            raise


app = _App(add_completion=False, no_args_is_help=True,
           help="Differentiable K&C suspension solver (units: mm, N, deg at the edge).")


@app.callback()
def _main(
    max_file_mb: Annotated[float | None, typer.Option(
        "--max-file-mb", help="Largest input file read, in MiB (default: 16 for model "
        "files, 512 for tables; also $DIFFSUSP_MAX_FILE_MB).", show_default=False)] = None,
):
    """diffsusp: static equilibrium, K&C analysis and identification of suspension models."""
    if max_file_mb is not None:
        if not (max_file_mb > 0 and max_file_mb != float("inf")):
            raise fail(f"--max-file-mb must be a positive number of MiB; got {max_file_mb}.",
                       EXIT_BAD_INPUT)
        os.environ["DIFFSUSP_MAX_FILE_MB"] = repr(float(max_file_mb))


def enable_x64():
    """float64, and a persistent compilation cache so that the second run of a command does
    not trace or compile again (`$DIFFSUSP_CACHE`, default `~/.cache/diffsusp/jax`; set it to an
    empty string to disable)."""
    from ..compilation import set_xla_flags

    set_xla_flags(os.environ)  # before JAX starts its backend
    import jax

    jax.config.update("jax_enable_x64", True)
    # One CPU device per core (when JAX has not started yet), and a table of cases split over
    # them (`solve_statics(devices=...)`) unless $DIFFSUSP_DEVICES says otherwise.
    os.environ.setdefault("DIFFSUSP_DEVICES", "all")
    try:
        jax.config.update("jax_num_cpu_devices", os.cpu_count() or 1)
    except RuntimeError:
        pass
    cache = os.environ.get("DIFFSUSP_CACHE", os.path.expanduser("~/.cache/diffsusp/jax"))
    if cache and not jax.config.jax_compilation_cache_dir:
        from ..compilation import enable_program_cache

        jax.config.update("jax_compilation_cache_dir", cache)
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
        enable_program_cache(os.path.join(cache, "programs"))  # and skip tracing (see there)


def console(stderr: bool = False, *, markup: bool = True) -> Console:
    """A Rich console; 120 columns when not a terminal (logs, test runners). With
    `markup=False` every string (printed, a table cell or title, a status line) is shown
    verbatim: use it wherever text comes from a file, a name or an argument."""
    c = Console(stderr=stderr, markup=markup)
    if not c.is_terminal:
        c = Console(stderr=stderr, width=120, markup=markup)
    return c


def plain(text) -> str:
    """`text` escaped for a Rich markup string: printed exactly as it is (`[v2]` stays)."""
    return escape(str(text))


def _labelled(label: str, style: str, message: str) -> Text:
    out = Text(f"{label}: ", style=style)
    out.append(str(message))
    return out


def fail(message: str, code: int) -> typer.Exit:
    """Print `message` verbatim on stderr and return the Exit to raise."""
    console(stderr=True).print(_labelled("error", "bold red", message), highlight=False)
    return typer.Exit(code=code)


def warn(message) -> None:
    """Print a warning verbatim on stderr (no Python source path or code line)."""
    console(stderr=True).print(_labelled("warning", "yellow", str(message)), highlight=False)


def show_warnings(caught, *, skip=()) -> list[str]:
    """Print each distinct recorded warning once (in order); return their texts."""
    seen = []
    for w in caught:
        text = str(w.message)
        if text in seen or any(s in text for s in skip):
            continue
        seen.append(text)
        warn(text)
    return seen


class Terminated(KeyboardInterrupt):
    """SIGTERM, delivered as an interruption so that long runs save what they finished."""


@contextlib.contextmanager
def interruptible():
    """SIGTERM raises `KeyboardInterrupt` (like SIGINT) inside the block, so that long runs
    can write the cases finished so far before they exit."""
    def handler(signum, frame):
        raise Terminated()

    try:
        previous = signal.signal(signal.SIGTERM, handler)
    except ValueError:  # not the main thread: leave SIGTERM alone
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


_WRITE_ERRNOS = (errno.ENOSPC, errno.EFBIG, errno.EDQUOT, errno.EROFS)


@contextlib.contextmanager
def cli_errors(*, record_warnings: bool = True):
    """Map the library's exceptions to messages and exit codes (bad input 2, non-convergence 3,
    unsolvable model 4, interrupted 130, anything else 1 without a traceback unless
    `$DIFFSUSP_DEBUG` is set), and print the warnings raised inside through the CLI's own
    format, after the block."""
    from diffsusp.errors import ConvergenceError, ModelError

    with contextlib.ExitStack() as stack:
        caught = []
        if record_warnings:
            caught = stack.enter_context(warnings.catch_warnings(record=True))
            warnings.simplefilter("always")

        def failed(message, code):
            show_warnings(caught)  # what led to the error first
            caught.clear()
            return fail(message, code)

        try:
            with interruptible():
                yield
        except (typer.Exit, typer.Abort, TyperException):  # usage errors: Typer words them
            raise
        except ConvergenceError as e:
            raise failed(str(e), EXIT_NOT_CONVERGED) from None
        except FileNotFoundError as e:
            raise failed(f"cannot read {e.filename}: {e.strerror}", EXIT_BAD_INPUT) from None
        except (IsADirectoryError, PermissionError) as e:
            raise failed(f"cannot access {e.filename}: {e.strerror}", EXIT_BAD_INPUT) from None
        except ModelError as e:
            code = EXIT_BAD_INPUT if getattr(e, "bad_input", False) else EXIT_MODEL_ERROR
            raise failed(str(e), code) from None
        except KeyboardInterrupt as e:
            what = "terminated (SIGTERM)" if isinstance(e, Terminated) else "interrupted"
            raise failed(f"{what}.", EXIT_INTERRUPTED) from None
        except MemoryError:
            raise failed("out of memory; use a smaller model or table.",
                         EXIT_BAD_INPUT) from None
        except Exception as e:
            if isinstance(e, OSError) and e.errno in _WRITE_ERRNOS:
                # a full disk, a file-size limit, a read-only file system: what could not be
                # known before the work; atomic writers leave no half file
                raise failed(f"cannot write {e.filename or 'an output file'}: {e.strerror}",
                             EXIT_BAD_INPUT) from None
            if os.environ.get("DIFFSUSP_DEBUG"):
                raise
            raise failed(f"internal error ({type(e).__name__}: {e}). This is a bug in "
                         "diffsusp; please report it with the command (set DIFFSUSP_DEBUG=1 "
                         "for the traceback).", EXIT_INTERNAL) from None
        finally:
            show_warnings(caught)


def check_output(path, *, suffixes=None, what: str = "output", directory: bool = False):
    """Fail (exit 2) before any work if `path` cannot be written: a file whose folder does not
    exist or is not writable, an existing directory where a file is expected (or the reverse),
    or a suffix outside `suffixes`. A missing `directory` is fine if it can be created."""
    if path is None:
        return
    text = os.fspath(path)
    suffix = os.path.splitext(text)[1].lower()
    if suffixes is not None and suffix not in suffixes:
        raise fail(f"{text}: unknown format '{suffix or '(no suffix)'}' for the {what}; use a "
                   f"{' or '.join(suffixes)} file.", EXIT_BAD_INPUT)
    if directory:
        target = text
        while target and not os.path.exists(target):
            parent = os.path.dirname(os.path.abspath(target))
            if parent == os.path.abspath(target):
                break
            target = parent
        if os.path.exists(text) and not os.path.isdir(text):
            raise fail(f"cannot write the {what} to {text}: it is a file, not a folder.",
                       EXIT_BAD_INPUT)
        if not os.path.isdir(target) or not os.access(target, os.W_OK | os.X_OK):
            raise fail(f"cannot write the {what} to {text}: {target} is not a writable folder.",
                       EXIT_BAD_INPUT)
        return
    if os.path.isdir(text):
        raise fail(f"cannot write the {what} to {text}: it is a directory.", EXIT_BAD_INPUT)
    folder = os.path.dirname(os.path.abspath(text))
    if not os.path.isdir(folder):
        raise fail(f"cannot write the {what} to {text}: the folder {folder} does not exist.",
                   EXIT_BAD_INPUT)
    if os.path.exists(text) and not os.access(text, os.W_OK):
        raise fail(f"cannot write the {what} to {text}: the file is not writable.",
                   EXIT_BAD_INPUT)
    if not os.access(folder, os.W_OK | os.X_OK):
        raise fail(f"cannot write the {what} to {text}: the folder {folder} is not writable.",
                   EXIT_BAD_INPUT)


def check_number(value, option: str, *, positive: bool = False, nonnegative: bool = False,
                 unit: str = ""):
    """Fail (exit 2, before any work) unless the value of `option` is a finite number (and > 0
    with `positive`, >= 0 with `nonnegative`): `--cutoff 0`, `--radius nan` and the like are
    bad input, not a run that ends in NaN or an internal error. None passes
    (an option not given)."""
    if value is None:
        return value
    v = float(value)
    if v != v or v in (float("inf"), float("-inf")):
        raise fail(f"{option} must be a finite number; got {value}.", EXIT_BAD_INPUT)
    if positive and not v > 0:
        raise fail(f"{option} must be a positive number{unit and f' [{unit}]'}; got {value}.",
                   EXIT_BAD_INPUT)
    if nonnegative and v < 0:
        raise fail(f"{option} must be a number >= 0{unit and f' [{unit}]'}; got {value}.",
                   EXIT_BAD_INPUT)
    return value


class Side(enum.StrEnum):
    """A side of the vehicle (`--side`)."""

    left = "left"
    right = "right"


SideOption = Annotated[Side | None, typer.Option(
    "--side", case_sensitive=False,
    help="the vehicle side to load the model on: a Chrono file is read on that side, any other "
    "half axle whose corner is on the other side is mirrored (default: as the model is)")]
"""The one `--side` option of every verb that loads a model."""


ModelArgument = Annotated[str, typer.Argument(
    help="Model file (.toml, .adm, .json) or built-in name.")]
"""The MODEL argument of every verb that loads a model (`load_model_file`)."""

JsonOption = Annotated[bool, typer.Option(
    "--json", help="Machine-readable output on stdout (JSON).")]
"""The one `--json` flag of the verbs."""

MeasurementsOption = Annotated[Path, typer.Option(
    "--measurements", "-m",
    help="Landmark or pose table with the loads of each case (.csv or .parquet).")]
"""The measurement table of the identification verbs (`diffsusp.measure.read_measurements`)."""

ReorderOption = Annotated[bool, typer.Option(
    help="Match landmarks probed in any order by their distance tables.")]
"""`--reorder` of the verbs that read measurements."""


def side_value(side) -> str | None:
    """The text of a `SideOption` value (None: as the model is)."""
    return None if side is None else Side(side).value


def load_model_file(model, *, check: bool = True, side=None):
    """The one model loader of the verbs that take a MODEL: a built-in name (`diffsusp.models.
    ZOO` or `STOP_VARIANTS`) or a model file (`diffsusp.io.MODEL_SUFFIXES`), through the
    library's one resolver (`diffsusp.resolve.load_model_file`), on `side` (a `SideOption`
    value). A name that is neither is bad input (`ModelFileError`, exit 2) that lists the
    built-in models."""
    from ..resolve import load_model_file as load

    return load(model, check=check, side=side_value(side))


def check_identify_outputs(out, write_model, figures=None):
    """The outputs of an identification verb, checked before any work (suffix, folder exists
    and is writable): the report (.csv, .json, .html), the identified model (.toml, .adm) and
    the figures folder."""
    check_output(out, suffixes=(".csv", ".json", ".html"), what="report")
    check_output(write_model, suffixes=(".toml", ".adm"), what="identified model")
    check_output(figures, what="figures folder", directory=True)


def write_model_file(mech, path, model_file) -> None:
    """An identified or corrected model to `path` by its suffix: .toml the native file; .adm
    the values written into the Adams dataset the model came from (`model_file.path`), or a
    complete dataset when it came from elsewhere."""
    import os

    if os.path.splitext(os.fspath(path))[1].lower() == ".toml":
        from ..io import save_model

        save_model(mech, path)
        return
    from ..io.adams import write_adm

    source = model_file.path
    template = source if source and os.path.splitext(str(source))[1].lower() == ".adm" else None
    write_adm(mech, path, template=template)


def listed(items, most: int = 10) -> str:
    """The first `most` items, comma-separated, then 'and N more' (the cases a message names)."""
    items = [str(i) for i in items]
    more = f" and {len(items) - most} more" if len(items) > most else ""
    return ", ".join(items[:most]) + more


def flagged_note(cases, subject: str, what: str, tail: str = ".") -> str:
    """'3 converged load cases with ...: 1, 4, 9.': the converged cases that a check
    (`diffsusp.statics.flagged_cases`) flags, for a warning; `subject` is singular ('load
    case'), `what` says what the check found."""
    n = len(cases)
    return f"{n} converged {subject}{'s' * (n != 1)} {what}: {listed(cases)}{tail}"


def nan_to_none(obj):
    """`obj` (nested dicts and lists) with every non-finite float replaced by None: valid JSON
    (`--json` output of the K&C verbs)."""
    import math

    if isinstance(obj, dict):
        return {k: nan_to_none(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [nan_to_none(v) for v in obj]
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


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
