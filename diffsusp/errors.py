"""The library's own error types. Each message names the field and says how to fix it."""


class ModelError(ValueError):
    """A mechanism that cannot be solved as given (unknown names, free parts, bad values)."""


class ConvergenceError(RuntimeError):
    """A static equilibrium that did not converge (the message gives the case and residual)."""


class ModelWarning(UserWarning):
    """A model that solves but is outside the validity of one of its laws."""


class InputError(ModelError):
    """Bad input from outside the library (a file, a table, a command-line argument).

    The CLI maps it to exit code 2; `ModelError` itself (a model that cannot be solved) maps to 4.
    """

    bad_input = True


def index_of(names, name: str, what: str = "parameter") -> int:
    """The position of `name` in `names`; an `InputError` naming the known ones if absent."""
    try:
        return list(names).index(name)
    except ValueError:
        raise InputError(f"unknown {what} {name!r}; known: {', '.join(names)}.") from None


class ModelFileError(InputError):
    """A model, load-case or table file that cannot be read: the message names the file, the line
    (1-based; None when the format has no lines) and the field, and says what is expected."""

    def __init__(self, message: str, *, path=None, line: int | None = None,
                 field: str | None = None):
        self.path, self.line, self.field = path, line, field
        where = str(path) if path is not None else "<input>"
        if line is not None:
            where += f":{line}"
        if field:
            where += f": {field}"
        super().__init__(f"{where}: {message}")
