"""The `diffsusp` command (Typer + Rich).

One module per verb or group of verbs, each with a `register(app)` that adds its verbs (named
`<verb>_command`) to the app or group it is given; they are all called below, in the order the
help lists them (commands, then groups). A verb parses its arguments, makes one library call
and formats the result. Shared pieces (the app, exit codes, the one model loader
`load_model_file`, the argument and option types every verb uses — `ModelArgument`,
`SideOption`, `JsonOption`, `MeasurementsOption`, `ReorderOption` — output checks, the wording
of flagged cases) are in `cli.common`.
Exit codes (`diffsusp.cli.common`): 0 success, 2 bad input (paths, files, tables, arguments),
3 a load case did not converge, 4 a model that cannot be solved as given.
"""

from . import (
    demo,
    fleet,
    geometry,
    identify,
    kc,
    model,
    rehearse,
    sensitivity,
    tyre,
    tyre_identify,
    tyre_onboard,
)
from .common import app

demo.register(app)
kc.register(app)
model.register(app)  # info, simulate
sensitivity.register(app)
rehearse.register(app)
identify.register(app)  # the identify group: direct, iterative, fit
geometry.register(identify.identify_app)  # identify geometry, identify correct
fleet.register(app)
tyre.register(app)  # the tyre group: info, eval, spec, rig, fit
tyre_identify.register(tyre.tyre_app)  # tyre identify
tyre_onboard.register(tyre.tyre_app)  # tyre onboard

__all__ = ["app"]

if __name__ == "__main__":  # pragma: no cover
    app()
