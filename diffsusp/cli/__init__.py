"""The `diffsusp` command (Typer + Rich).

One module per group of verbs; each registers its commands on `app` when imported below.
Exit codes (`diffsusp.cli.common`): 0 success, 2 bad input (paths, files, tables, arguments),
3 a load case did not converge, 4 a model that cannot be solved as given.
"""

from . import demo, geometry, identify, kc, model, sensitivity, tyre  # noqa: F401  (each module registers its verbs on `app`)
from .common import app

__all__ = ["app"]

if __name__ == "__main__":  # pragma: no cover
    app()
