"""The `diffsusp` command (Typer + Rich).

One module per group of verbs; the verbs are registered on `app` below, explicitly (the tyre
group, `cli.tyre`, still registers itself on import).
Exit codes (`diffsusp.cli.common`): 0 success, 2 bad input (paths, files, tables, arguments),
3 a load case did not converge, 4 a model that cannot be solved as given.
"""

from . import demo, fleet, geometry, identify, kc, model, rehearse, sensitivity
from .common import app

# The verbs, registered here explicitly (help lists commands in this order, then groups).
app.command("demo")(demo.demo)
app.command("kc")(kc.kc_command)
app.command("info")(model.info)
app.command("simulate")(model.simulate)
app.command("sensitivity")(sensitivity.sensitivity_command)
app.command("rehearse")(rehearse.rehearse_command)
app.add_typer(identify.identify_app, name="identify")
identify.identify_app.command("direct")(identify.direct)
identify.identify_app.command("iterative")(identify.iterative_command)
identify.identify_app.command("fit")(identify.fit_command)
identify.identify_app.command("geometry")(geometry.geometry)
identify.identify_app.command("correct")(geometry.correct)
app.add_typer(fleet.fleet_app, name="fleet")  # its verbs register in cli/fleet.py

from . import tyre  # noqa: E402, F401  (registers its group on import, after identify)

__all__ = ["app"]

if __name__ == "__main__":  # pragma: no cover
    app()
