"""`diffsusp rehearse METHOD MODEL`: before measuring, rehearse the planned experiment — random
truths around the start, the measurements simulated with the planned noise, the method run on
each, and per parameter how often it is identified and how often "identified" is right
(`diffsusp.identify.rehearse`).

Methods: `direct`, `iterative`, `least-squares` (MODEL: a built-in model or a model file; the
truths are its bushing stiffnesses × a log-uniform factor in `--spread`, default 0.5–2; the
measurements four landmarks per part with σ `--noise` mm), `mf-fit` (MODEL: the start `.tir`
file; the truths its coefficients × (1 ± `--spread`), default ±20 %; the measurements the file's
bench programme with σ = a + b·|F|, `--noise a,b`, default 20 N + 1 %), `geometry` (MODEL: a
built-in model or a model file; the truths its located joints' hardpoints displaced by a uniform
±`--spread` mm per coordinate, default 5; `--params`: the joints to locate, default every joint
the model implies; the measurements four landmarks per part with σ `--noise` mm, default 0.05),
`onboard` (MODEL: `synthetic`, the library's synthetic 12-DOF car, `diffsusp.tyre.vehicle`;
the truths the 8 coefficients of its reduced tyre model (4-16…4-18) × (1 ± `--spread`), default
±20 %, `--params` the coefficients drawn; the measurements the steering-wheel sine of
`--duration` s (default 6) recorded by its sensors with their σ × `--noise` (default 1), the
Correvit `--delay` s late (default 0); the pipeline `diffsusp.tyre.onboard.identify`, the
delay estimated and removed, "all" wheels pooled, camber in).
"""

import enum
import math
from pathlib import Path
from typing import Annotated

import typer

from .common import EXIT_BAD_INPUT, check_output, cli_errors, console, enable_x64, fail, print_json

Method = enum.StrEnum("Method", {v: v for v in ("direct", "iterative", "least-squares",
                                                 "mf-fit", "geometry", "onboard")})
ONBOARD_MODELS = ("synthetic",)
Cases = enum.StrEnum("Cases", {v: v for v in ("corner", "thesis")})


def _floats(text: str, what: str) -> list[float]:
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        raise fail(f"--{what} must be numbers separated by commas; got {text!r}.",
                   EXIT_BAD_INPUT) from None
    if not all(math.isfinite(v) for v in values):
        raise fail(f"--{what} must be finite; got {text!r}.", EXIT_BAD_INPUT)
    return values


def register(app: typer.Typer) -> None:
    """Add `rehearse` to `app`."""
    app.command("rehearse")(rehearse_command)


def rehearse_command(
    method: Annotated[Method, typer.Argument(help="The identification to rehearse.")],
    model: Annotated[str, typer.Argument(
        help="Start model: built-in name or model file (mf-fit: the start .tir file; "
        "onboard: 'synthetic', the synthetic car).")],
    n: Annotated[int, typer.Option("--n", help="Random truths.")] = 200,
    seed: Annotated[int, typer.Option(help="Seed of the truths and the noise.")] = 0,
    noise: Annotated[str | None, typer.Option(
        help="Measurement noise: landmark σ in mm (suspension, default 0.05); 'a,b' for "
        "σ = a + b·|F| in N (mf-fit, default 20,0.01); a factor on the car's sensor σ "
        "(onboard, default 1).")] = None,
    spread: Annotated[str | None, typer.Option(
        help="Spread of the truths: 'low,high' factors on the stiffnesses (default 0.5,2); "
        "a relative ± on the MF coefficients / the on-board tyre coefficients (default 0.2); "
        "± mm on the joint hardpoints (geometry, default 5).")] = None,
    params: Annotated[str | None, typer.Option(
        help="Parameters to draw and identify, comma-separated (default: every non-zero "
        "bushing stiffness / every coefficient the fit estimates / every joint the model "
        "implies, by joint name for geometry / every on-board tyre coefficient).")] = None,
    cases: Annotated[Cases, typer.Option(
        help="Load cases (suspension): the corner's combined-load grid, or the thesis's "
        "Table 5-1.")] = Cases.corner,
    delay: Annotated[float, typer.Option(
        help="onboard: the Correvit's delay [s] in the simulated records (the pipeline "
        "estimates and removes it).")] = 0.0,
    duration: Annotated[float, typer.Option(
        help="onboard: length of the steering-wheel sine [s].")] = 6.0,
    out: Annotated[Path | None, typer.Option(help="Write the rehearsal (.csv or .json).")]
    = None,
    json_output: Annotated[bool, typer.Option("--json", help="JSON on stdout.")] = False,
):
    """Rehearse an identification on random truths before measuring: per parameter, how often
    the planned experiment identifies it and how often "identified" is right (within 3σ)."""
    check_output(out, suffixes=(".csv", ".json"), what="rehearsal")
    if n < 1:
        raise fail(f"--n must be at least 1 random truth; got {n}.", EXIT_BAD_INPUT)
    method = Method(method).value
    enable_x64()
    from ..identify import SuspensionScenario, rehearse

    with cli_errors():
        if method == "mf-fit":
            scenario = _mf_scenario(model, noise, spread, params)
        elif method == "geometry":
            scenario = _geometry_scenario(model, noise, spread, params, cases)
        elif method == "onboard":
            scenario = _onboard_scenario(model, noise, spread, params, delay, duration, n)
        else:
            from .common import load_model_file

            mech = load_model_file(model).mechanism
            sigma = _floats(noise, "noise") if noise is not None else [0.05]
            if len(sigma) != 1 or not sigma[0] > 0:
                raise fail(f"--noise must be one positive landmark σ (mm); got {noise!r} (a "
                           "noise of 0 would call everything identified with σ = 0).",
                           EXIT_BAD_INPUT)
            factors = _floats(spread, "spread") if spread is not None else [0.5, 2.0]
            if len(factors) != 2 or not 0 < factors[0] < factors[1]:
                raise fail(f"--spread must be 'low,high' factors with 0 < low < high; got "
                           f"{spread!r}.", EXIT_BAD_INPUT)
            names = [n.strip() for n in params.split(",")] if params else None
            scenario = SuspensionScenario(method.replace("-", "_"), mech, _loads(mech, cases),
                                          names, noise=sigma[0], spread=tuple(factors))
        report = rehearse(scenario, n=n, seed=seed)
        if out is not None:
            report.write(out)
    if json_output:
        print_json(report.summary())
        return
    con = console(markup=False)
    con.print(report.table(), highlight=False, soft_wrap=True)
    if out is not None:
        con.print(f"rehearsal written to {out}", highlight=False)


def _mf_scenario(path: str, noise, spread, params):
    from ..io.tir import read_tir
    from ..tyre import fit as F
    from ..tyre.mf6 import MagicFormula6

    tir = read_tir(path)
    start = MagicFormula6.from_tir(tir)
    ab = _floats(noise, "noise") if noise is not None else [20.0, 0.01]
    if len(ab) != 2 or ab[0] < 0 or ab[1] < 0 or not (ab[0] > 0 or ab[1] > 0):
        raise fail(f"--noise must be 'a,b' (σ = a + b·|F|, N) with a or b > 0; got {noise!r}.",
                   EXIT_BAD_INPUT)
    rel = _floats(spread, "spread") if spread is not None else [0.2]
    if len(rel) != 1 or not rel[0] > 0:
        raise fail(f"--spread must be one relative spread > 0 (0.2 = ±20 %); got {spread!r}.",
                   EXIT_BAD_INPUT)
    programme = F.bench_programme(start, channels=("FY",))
    names = [n.strip() for n in params.split(",")] if params else None
    return F.FitRehearsal(start, programme, names, spread=rel[0],
                          noise={"FY": (ab[0], ab[1])}, tir=tir)


def _geometry_scenario(model: str, noise, spread, params, cases):
    from ..identify import GeometryScenario
    from .common import load_model_file

    mech = load_model_file(model).mechanism
    sigma = _floats(noise, "noise") if noise is not None else [0.05]
    if len(sigma) != 1 or not sigma[0] > 0:
        raise fail(f"--noise must be one positive landmark σ (mm); got {noise!r} (a noise of 0 "
                   "would call everything identified with σ = 0).", EXIT_BAD_INPUT)
    mm = _floats(spread, "spread") if spread is not None else [5.0]
    if len(mm) != 1 or not mm[0] > 0:
        raise fail(f"--spread must be one displacement > 0 (mm) of the joint hardpoints; got "
                   f"{spread!r}.", EXIT_BAD_INPUT)
    names = [n.strip() for n in params.split(",")] if params else None
    return GeometryScenario(mech, _loads(mech, cases), names, noise=sigma[0], spread=mm[0])


def _loads(mech, cases):
    """The load table `--cases` names: the thesis's, or None: the scenario's default (the
    corner's combined-load grid, `identify.rehearse.corner_cases`)."""
    from ..kc.loadcases import thesis_load_cases

    return thesis_load_cases(mech) if cases == Cases.thesis else None


def _onboard_scenario(model: str, noise, spread, params, delay, duration, n):
    import dataclasses

    from ..tyre import onboard
    from ..tyre.onboard_rehearse import OnboardScenario
    from ..tyre.vehicle import Sensors

    if model not in ONBOARD_MODELS:
        raise fail(f"onboard: MODEL must be one of {', '.join(ONBOARD_MODELS)} (the library's "
                   f"synthetic 12-DOF car); got {model!r}.", EXIT_BAD_INPUT)
    scale = _floats(noise, "noise") if noise is not None else [1.0]
    if len(scale) != 1 or not scale[0] > 0:
        raise fail(f"--noise must be one positive factor on the sensors' σ; got {noise!r} (a "
                   "noise of 0 would call everything identified with σ = 0).", EXIT_BAD_INPUT)
    rel = _floats(spread, "spread") if spread is not None else [0.2]
    if len(rel) != 1 or not 0 < rel[0] < 1:
        raise fail(f"--spread must be one relative spread in (0, 1) (0.2 = ±20 %); got "
                   f"{spread!r}.", EXIT_BAD_INPUT)
    for value, option in ((delay, "--delay"), (duration, "--duration")):
        if not (math.isfinite(value) and value >= 0):
            raise fail(f"{option} must be a finite number of seconds >= 0; got {value}.",
                       EXIT_BAD_INPUT)
    wanted = None
    if params:
        wanted = tuple(n.strip() for n in params.split(",") if n.strip())
        unknown = [n for n in wanted if n not in onboard.NAMES]
        if unknown or not wanted:
            raise fail(f"unknown parameter(s) {', '.join(unknown) or repr(params)}; the reduced "
                       f"tyre model's: {', '.join(onboard.NAMES)}.", EXIT_BAD_INPUT)
    default = Sensors()
    fields = ("sigma_laser", "sigma_correvit", "sigma_gyro", "sigma_imu_velocity",
              "sigma_accelerometer", "sigma_travel", "sigma_steer", "sigma_spin", "sigma_force",
              "sigma_moment")
    sensors = Sensors(**{f: scale[0] * getattr(default, f) for f in fields})
    weights = onboard.Options()
    options = dataclasses.replace(weights, **{f: scale[0] * getattr(weights, f) for f in (
        "sigma_laser", "sigma_correvit", "sigma_gyro", "sigma_imu_velocity")})
    return OnboardScenario(sensors=sensors, spread=rel[0], delay=float(delay),
                           duration=float(duration), options=options, params=wanted,
                           batch=min(n, 20))
