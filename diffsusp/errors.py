"""The library's own error types. Each message names the field and says how to fix it."""


class ModelError(ValueError):
    """A mechanism that cannot be solved as given (unknown names, free parts, bad values)."""


class ConvergenceError(RuntimeError):
    """A static equilibrium that did not converge (the message gives the case and residual)."""


class ModelWarning(UserWarning):
    """A model that solves but is outside the validity of one of its laws."""
