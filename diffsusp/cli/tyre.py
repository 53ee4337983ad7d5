"""`diffsusp tyre info|eval|spec|rig|fit`: Magic Formula tyre property files (spec: tyre §7 C);
`identify` and `onboard` (the polynomial and on-board identifications) are in `cli.tyre_identify`
and `cli.tyre_onboard`.

- `info FILE.tir`: version, dimensions, nominal load, ranges, coefficient counts.
- `eval FILE.tir --inputs TABLE --out RESULTS` (or `--grid`): steady-state forces and moments.
  Input columns `FZ` [N], `SL` [-], `SA` [rad], `IA` [rad], `P` [Pa], `VX` [m/s] (units in
  brackets, e.g. `SA [deg]`, `P [kPa]`, `VX [km/h]`; missing SL/SA/IA are 0, P is INFLPRES, VX
  LONGVL). Output: the inputs plus `FX`, `FY` [N], `MX`, `MY`, `MZ` [N·m]. Default behaviour
  that of TNO MF-Tyre as MFeval reproduces it: no α* (`--alpha-star` to use it), limit checks
  on (inputs beyond the file's ranges are warned about and saturated; `--no-limits`).
- `spec FILE.tir [--loads 2000,4000,6000]`: the specification quantities over loads (cornering
  and slip stiffness, trail, peaks, camber stiffness, values at zero slip).
- `rig FILE.tir --model pseudo_mcpherson --slip-angle -4:4:9 [--fz 4500]`: the tyre on the
  K&C rig (`diffsusp.tyre.rig`): the coupled tyre–suspension equilibrium at commanded slip
  angles [deg, ISO-W], slip ratio and camber offset [deg, K&C sense]; output per case: the
  tyre's effective slip angle and inclination, the corner's toe and camber, FX, FY [N], MX,
  MY, MZ [N·m] (ISO-W); `--out` a table, `--json`.
- `fit DATA --model mf61|mf62|mf52|mf1989 [--start FILE.tir] --out FITTED.tir`: coefficients from
  bench data (columns as `eval`'s plus the measured FX, FY, MZ [N, N·m]); `--mode` chooses the
  coefficient groups (`diffsusp.tyre.fit.GROUPS`), fitted together by the staged strategy
  (starting values from the data, zero camber, camber, joint); any sign of a start coefficient
  (PAC2002 files write PDY1 < 0); coefficients the start file does not use are held (`--free`
  to fit them); `--noise CH=a,b` (σ = a + b·|F|, default estimated from the sweeps); report to
  the terminal (and `--report` .json), a verdict ("does not fit the data": exit code 3),
  measured-vs-fitted figures per load and camber to `--figures`.

Exit codes as the other verbs: 2 bad input, 4 a model that cannot be evaluated.
"""

import enum
import json
import math
import warnings
from pathlib import Path
from typing import Annotated

import numpy as np
import typer
from rich import box
from rich.table import Table as RichTable

from .common import (
    EXIT_BAD_INPUT,
    check_number,
    check_output,
    cli_errors,
    console,
    enable_x64,
    fail,
    load_model_file,
    plain,
    print_json,
    warn,
)

tyre_app = typer.Typer(add_completion=False, no_args_is_help=True,
                       help="Magic Formula tyre models (.tir files): evaluate, specify, fit.")
"""The `tyre` group: `info`, `eval`, `spec`, `rig`, `fit` here, `identify` in
`cli.tyre_identify`, `onboard` in `cli.tyre_onboard` (each registered by its `register`)."""


def register(app: typer.Typer) -> None:
    """Add the `tyre` group to `app`, with its verbs `info`, `eval`, `spec`, `rig` and `fit`."""
    app.add_typer(tyre_app, name="tyre")
    tyre_app.command("info")(info_command)
    tyre_app.command("eval")(eval_command)
    tyre_app.command("spec")(spec_command)
    tyre_app.command("rig")(rig_command)
    tyre_app.command("fit")(fit_command)

_MODES = {"pure_lateral", "pure_longitudinal", "pure_aligning", "combined_longitudinal",
          "combined_lateral", "pressure", "overturning", "mf1989_lateral", "mf1989_aligning",
          "mf1989_longitudinal"}
# The choices of `tyre fit` (Typer checks them: exit code 2).
FitModel = enum.StrEnum("FitModel", {v: v for v in ("mf61", "mf62", "mf52", "mf1989")})
Mode = enum.StrEnum("Mode", {v: v for v in sorted(_MODES)})
Loss = enum.StrEnum("Loss", {v: v for v in ("linear", "huber", "cauchy")})  # tyre.fit.LOSSES


def _load(path: Path):
    from diffsusp.io.tir import read_tir
    from diffsusp.tyre import MagicFormula6

    tir = read_tir(path)
    return tir, MagicFormula6.from_tir(tir)


def info_command(file: Annotated[Path, typer.Argument(help="Tyre property file (.tir).")],
         json_out: Annotated[bool, typer.Option("--json", help="Machine-readable.")] = False):
    """Summary of a .tir file: Magic Formula version, dimensions, ranges."""
    with cli_errors():
        enable_x64()
        tir, model = _load(file)
        lim = model.limit
        out = {"file": str(file), "fittyp": tir.fittyp, "version": model.version,
               "unloaded_radius_m": float(model["UNLOADED_RADIUS"]) / 1000.0,
               "fnomin_N": float(model["FNOMIN"]), "nompres_Pa": float(model["NOMPRES"]),
               "longvl_m_s": float(model["LONGVL"]) / 1000.0,
               "limits": {k: (v if math.isfinite(v) else None) for k, v in lim.items()},
               "coefficients_in_file": len(tir.entries),
               "sections": list(tir.sections)}
    if json_out:
        print_json(out)
        return
    c = console(markup=False)
    c.print(f"{file}: FITTYP {out['fittyp']} (MF {out['version']}), R0 "
            f"{out['unloaded_radius_m']:.4g} m, FNOMIN {out['fnomin_N']:.6g} N, NOMPRES "
            f"{out['nompres_Pa']:.6g} Pa, LONGVL {out['longvl_m_s']:.4g} m/s")
    t = RichTable(box=box.SIMPLE)
    for h in ("range", "min", "max"):
        t.add_column(h)
    for name, lo, hi in (("FZ [N]", "FZMIN", "FZMAX"), ("kappa [-]", "KPUMIN", "KPUMAX"),
                         ("alpha [rad]", "ALPMIN", "ALPMAX"), ("gamma [rad]", "CAMMIN", "CAMMAX"),
                         ("pressure [Pa]", "PRESMIN", "PRESMAX")):
        t.add_row(name, f"{lim[lo]:g}", f"{lim[hi]:g}")
    c.print(t)
    c.print(f"{out['coefficients_in_file']} entries in {len(out['sections'])} sections")


def eval_command(
    file: Annotated[Path, typer.Argument(help="Tyre property file (.tir).")],
    inputs: Annotated[Path | None, typer.Option(
        help=plain("Input table: FZ [N], SL [-], SA [rad], IA [rad], P [Pa], VX [m/s] "
                   "(.csv/.parquet; the table `--out` writes reads back)."))]
    = None,
    out: Annotated[Path | None, typer.Option(help="Results table (.csv or .parquet).")] = None,
    grid: Annotated[bool, typer.Option(
        help="A quick sweep: FNOMIN × {0.5, 1, 1.5}, slip angle −15…15°, κ = 0.")] = False,
    alpha_star: Annotated[bool, typer.Option(help="Use α* = tan α, γ* = sin γ.")] = False,
    limits: Annotated[bool, typer.Option(help="Limit checks (saturate at the file's ranges).")]
    = True,
    pure: Annotated[bool, typer.Option(help="Pure-slip functions instead of combined.")] = False,
):
    """Steady-state forces and moments of a .tir tyre at the given inputs."""
    import jax.numpy as jnp

    from diffsusp.io.tables import write_table
    from diffsusp.tyre import check_limits, evaluate
    from diffsusp.tyre import fit as F

    if (inputs is None) == (not grid):
        raise fail("give exactly one of --inputs TABLE and --grid", EXIT_BAD_INPUT)
    check_output(out, suffixes=(".csv", ".parquet"), what="results table")
    with cli_errors():
        enable_x64()
        tir, model = _load(file)
        if grid:
            # within the file's own validity ranges (0.5-1.5 FNOMIN, ±15° where they allow)
            lim, fnom = model.limit, float(model["FNOMIN"])
            flo = max(0.5 * fnom, lim.get("FZMIN", 0.0))
            fhi = min(1.5 * fnom, lim.get("FZMAX", math.inf))
            alo = max(-math.radians(15.0), lim.get("ALPMIN", -math.inf))
            ahi = min(math.radians(15.0), lim.get("ALPMAX", math.inf))
            fz = np.repeat(np.linspace(flo, fhi, 3) if fhi > flo else np.array([fnom]) * 1.0,
                           31)
            sa = np.tile(np.linspace(alo, ahi, 31), fz.size // 31)
            z = np.zeros(fz.size)
            cols = {"FZ": fz, "SL": z, "SA": sa, "IA": z, "P": z + float(model["INFLPRES"]),
                    "VX": z + float(model["LONGVL"])}
        else:
            from diffsusp.tyre.input_tables import read_tyre_table

            cols = F.input_columns(read_tyre_table(inputs, "input table"))
        p = np.where(np.isnan(cols["P"]), float(model["INFLPRES"]), cols["P"])
        vx = np.where(np.isnan(cols["VX"]), float(model["LONGVL"]), cols["VX"])
        if limits:
            with warnings.catch_warnings(record=True) as rec:
                warnings.simplefilter("always")
                check_limits(model, fz=cols["FZ"], kappa=cols["SL"], alpha=cols["SA"],
                             gamma=cols["IA"], pressure=p, where=f"{inputs or 'grid'}: ",
                             combined=not pure)
            for w in rec:
                warn(w.message)
        f = evaluate(model, jnp.asarray(cols["FZ"]), jnp.asarray(cols["SL"]),
                     jnp.asarray(cols["SA"]), jnp.asarray(cols["IA"]), jnp.asarray(vx),
                     jnp.asarray(p), combined=not pure, limits=limits, alpha_star=alpha_star,
                     announce=False)   # check_limits above named the table's rows
        res = {"FZ": cols["FZ"], "SL": cols["SL"], "SA": cols["SA"], "IA": cols["IA"], "P": p,
               "VX": vx / 1000.0, "FX": np.asarray(f.fx), "FY": np.asarray(f.fy),
               "MX": np.asarray(f.mx) / 1000.0, "MY": np.asarray(f.my) / 1000.0,
               "MZ": np.asarray(f.mz) / 1000.0}
        units = {"FZ": "N", "SL": "-", "SA": "rad", "IA": "rad", "P": None, "VX": None,
                 "FX": "N", "FY": "N", "MX": "N·m", "MY": "N·m", "MZ": "N·m"}
        if out is not None:
            # P [Pa] and VX [m/s] are written without brackets: not table units of the library
            write_table(out, {("P_Pa" if k == "P" else "VX_m_s" if k == "VX" else k): v
                              for k, v in res.items()},
                        {("P_Pa" if k == "P" else "VX_m_s" if k == "VX" else k): u
                         for k, u in units.items()})
    c = console(markup=False)
    if out is not None:
        c.print(f"{len(res['FZ'])} points written to {out}")
    else:
        t = RichTable(box=box.SIMPLE)
        for k in ("FZ", "SL", "SA", "IA", "FX", "FY", "MZ"):
            t.add_column(f"{k} [{units[k]}]", justify="right")
        for i in range(min(len(res["FZ"]), 40)):
            t.add_row(*(f"{res[k][i]:.5g}" for k in ("FZ", "SL", "SA", "IA", "FX", "FY", "MZ")))
        c.print(t)


def _parse_loads(text: str) -> list[float]:
    """The loads of `--loads`: finite and > 0 [N], at least one."""
    try:
        loads = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise fail(f"--loads must be numbers separated by commas, got '{text}'",
                   EXIT_BAD_INPUT) from None
    if not loads:
        raise fail(f"--loads '{text}' holds no load; give loads [N] separated by commas, e.g. "
                   "2000,4000,6000", EXIT_BAD_INPUT)
    bad = [v for v in loads if not (math.isfinite(v) and v > 0)]
    if bad:
        raise fail(f"--loads: every load must be a finite number > 0 [N]; got {bad[0]:g}",
                   EXIT_BAD_INPUT)
    return loads


def spec_command(
    file: Annotated[Path, typer.Argument(help="Tyre property file (.tir).")],
    loads: Annotated[str | None, typer.Option(
        help="Loads [N], comma separated (default FNOMIN × 0.5, 0.75, 1, 1.25, 1.5).")] = None,
    json_out: Annotated[bool, typer.Option("--json", help="Machine-readable.")] = False,
):
    """Specification quantities over loads (exact derivatives; pure slip, camber 0)."""
    from diffsusp.tyre import specification
    from diffsusp.tyre.spec import to_rows

    given = _parse_loads(loads) if loads is not None else None
    with cli_errors():
        enable_x64()
        tir, model = _load(file)
        fz = (given if given is not None else
              [f * float(model["FNOMIN"]) for f in (0.5, 0.75, 1.0, 1.25, 1.5)])
        fzmax = float(model.limit.get("FZMAX", math.inf))
        beyond = [v for v in fz if v > fzmax]
        if beyond:
            warn(f"--loads {', '.join(f'{v:g}' for v in beyond)} N beyond FZMAX = {fzmax:g} N "
                 f"of {file} [VERTICAL_FORCE_RANGE]: outside the file's validity range")
        rows = to_rows(specification(model, np.array(fz)))
    if json_out:
        print_json(rows)
        return
    # one row per quantity, one column per load: as narrow as the number of loads, whatever
    # the quantities (eleven columns would not fit a terminal)
    show = [("cornering_stiffness", "C_alpha [N/deg]", math.radians(1.0)),
            ("pneumatic_trail", "trail [mm]", 1), ("slip_stiffness", "C_kappa [N/-]", 1),
            ("camber_stiffness", "C_gamma [N/deg]", math.radians(1.0)),
            ("fy_peak", "FY peak [N]", 1),
            ("alpha_at_fy_peak", "  at alpha [deg]", math.degrees(1.0)),
            ("mu_y", "mu_y [-]", 1),
            ("fx_peak", "FX peak, braking [N]", 1), ("kappa_at_fx_peak", "  at kappa [-]", 1),
            ("mu_x", "mu_x [-]", 1),
            ("mz_peak", "MZ peak [N·m]", 1e-3), ("alpha_at_mz_peak", "  at alpha [deg]",
                                                math.degrees(1.0)),
            ("fy_at_zero", "FY(0) [N]", 1), ("mz_at_zero", "MZ(0) [N·m]", 1e-3)]
    t = RichTable(box=box.SIMPLE)
    t.add_column("FZ [N]", no_wrap=True)
    for r in rows:
        t.add_column(f"{r['fz']:.6g}", justify="right", no_wrap=True)
    for k, h, scale in show:
        t.add_row(h, *(f"{r[k] * scale:.6g}" for r in rows))
    console(markup=False).print(t)


def rig_command(
    file: Annotated[Path, typer.Argument(help="Tyre property file (.tir).")],
    model: Annotated[str, typer.Option(
        help="Suspension: a built-in model name or a model file.")] = "pseudo_mcpherson",
    slip_angle: Annotated[str, typer.Option(
        help=plain("Commanded slip angles [deg, ISO-W]: start:stop:count or one number."))]
    = "-4:4:9",
    fz: Annotated[float | None, typer.Option(
        help="Vertical load [N] (default: the corner's design load).")] = None,
    slip_ratio: Annotated[float, typer.Option(help="Slip ratio κ [-].")] = 0.0,
    camber_offset: Annotated[float, typer.Option(
        help=plain("Added to the corner's camber [deg, top outboard +]."))] = 0.0,
    longitudinal_at: Annotated[str, typer.Option(
        help="contact_patch (brake torque on the carrier) | wheel_centre (drive shaft).")]
    = "contact_patch",
    out: Annotated[Path | None, typer.Option(help="Results table (.csv or .parquet).")] = None,
    json_out: Annotated[bool, typer.Option("--json", help="Machine-readable.")] = False,
):
    """The tyre on the K&C rig: forces at commanded slip with the suspension's compliance."""
    import jax.numpy as jnp

    from diffsusp.io.tables import write_table
    from diffsusp.kc.dispatch import parse_range
    from diffsusp.tyre import rig as tyre_rig

    check_output(out, suffixes=(".csv", ".parquet"), what="results table")
    check_number(fz, "--fz", positive=True, unit="N")
    check_number(slip_ratio, "--slip-ratio")
    check_number(camber_offset, "--camber-offset")
    with cli_errors():
        alpha = np.radians(parse_range(slip_angle, "slip-angle"))
        if alpha.size > MAX_RIG_CASES or not np.isfinite(alpha).all():
            raise fail(f"--slip-angle '{slip_angle}': {alpha.size} case(s); give at most "
                       f"{MAX_RIG_CASES} finite angles [deg]", EXIT_BAD_INPUT)
        enable_x64()
        _, tyre = _load(file)
        mech = load_model_file(model).mechanism
        if hasattr(tyre, "limit"):   # the range warnings of `tyre eval`
            from diffsusp.tyre import check_limits

            check_limits(tyre, fz=None if fz is None else [fz],
                         kappa=np.full(alpha.size, slip_ratio), alpha=alpha,
                         gamma=[math.radians(camber_offset)], where=f"{file}: ")
        if np.abs(alpha).max() >= math.pi / 2 or abs(camber_offset) >= 90.0:
            warn("a commanded slip angle or camber offset of 90° or more: the tyre is "
                 "side-on to the road; the result is not a tyre on a rig")
        rig = tyre_rig.tyre_rig(mech, tyre, longitudinal_at=longitudinal_at)
        sol = tyre_rig.solve(rig, jnp.asarray(alpha), fz=fz, slip_ratio=slip_ratio,
                             camber_offset=math.radians(camber_offset))
        res = {"SA_CMD": np.degrees(alpha), "SA": np.degrees(np.asarray(sol.slip_angle)),
               "IA": np.degrees(np.asarray(sol.inclination)),
               "TOE": np.degrees(np.asarray(sol.toe)), "CAMBER": np.degrees(np.asarray(sol.camber)),
               "FZ": np.full(alpha.size, float(rig.corner.design_load if fz is None else fz)),
               "FX": np.asarray(sol.forces.fx), "FY": np.asarray(sol.forces.fy),
               "MX": np.asarray(sol.forces.mx) / 1000.0,
               "MY": np.asarray(sol.forces.my) / 1000.0,
               "MZ": np.asarray(sol.forces.mz) / 1000.0}
        units = {"SA_CMD": "deg", "SA": "deg", "IA": "deg", "TOE": "deg", "CAMBER": "deg",
                 "FZ": "N", "FX": "N", "FY": "N", "MX": "N·m", "MY": "N·m", "MZ": "N·m"}
        if out is not None:
            write_table(out, res, units)
    if json_out:
        print_json([{k: float(v[i]) for k, v in res.items()} for i in range(alpha.size)])
        return
    c = console(markup=False)
    if out is not None:
        c.print(f"{alpha.size} cases written to {out}")
        return
    t = RichTable(box=box.SIMPLE, title=f"{mech.name} with {file.name} (ISO-W tyre axes)")
    for k in res:
        t.add_column(f"{k} [{units[k]}]", justify="right")
    for i in range(alpha.size):
        t.add_row(*(f"{res[k][i]:.5g}" for k in res))
    c.print(t)


MAX_RIG_CASES = 10_000
"""Most commanded slip angles of one `tyre rig` run (10⁷ cases exhaust memory)."""


def fit_command(
    data: Annotated[Path, typer.Argument(
        help="Bench data (.csv/.parquet): inputs and FX, FY, MZ.")],
    model: Annotated[FitModel, typer.Option(help="Magic Formula version.")] = FitModel.mf61,
    start: Annotated[Path | None, typer.Option(help="Start .tir (MF 5.2/6.x).")] = None,
    out: Annotated[Path | None, typer.Option(help="Write the fitted .tir here.")] = None,
    mode: Annotated[list[Mode] | None, typer.Option(
        help="Coefficient group(s) fitted together (default: pure_lateral, pure_longitudinal, "
        "pure_aligning as the data allow; mf1989: mf1989_lateral).")] = None,
    loss: Annotated[Loss, typer.Option(help="Robust loss of the residuals.")] = Loss.huber,
    noise: Annotated[list[str] | None, typer.Option(
        help="Noise of a channel, CH=a or CH=a,b for sigma = a + b|F| [N, N·m] (default: "
        "estimated from the sweeps).")] = None,
    free: Annotated[list[str] | None, typer.Option(
        help="Fit a coefficient the start file does not use (0 or absent: held by "
        "default).")] = None,
    strategy: Annotated[str, typer.Option(
        help="staged (start values from the data, zero camber, camber, joint) or joint.")]
    = "staged",
    report: Annotated[Path | None, typer.Option(
        help="Write the report (.json, .csv or .html).")] = None,
    figures: Annotated[Path | None, typer.Option(help="Measured-vs-fitted figures folder.")]
    = None,
    max_steps: Annotated[int, typer.Option(
        help="Most Levenberg-Marquardt steps per stage.", min=1)] = 200,
    keep_unconverged: Annotated[bool, typer.Option(
        help="Write --out even when the optimiser did not converge (the file is marked).")]
    = False,
):
    """Fit Magic Formula coefficients to bench data (robust LM, σ and a verdict per coefficient).

    Exit code 3 when the fitted model does not fit the data (its residual is far above the
    noise): the report and the files are still written, nothing is called identified. Exit
    code 3 too when the optimiser did not converge: the report is written, the fitted .tir only
    with --keep-unconverged (and marked NOT CONVERGED in its first line). Checked before the
    fit (exit 2): the table (`diffsusp.tyre.input_tables`), data that vary (at least as many
    distinct input points as free coefficients). Channels the model has no output for (MX, MY
    for mf1989) are noted and left out."""
    from diffsusp.tyre import MagicFormula89
    from diffsusp.tyre import fit as F

    model, loss = FitModel(model).value, Loss(loss).value
    mode = [Mode(m).value for m in mode] if mode else None
    if model != "mf1989" and start is None:
        raise fail("--start FILE.tir is needed for mf61/mf62/mf52 (the start values and the "
                   "file's other sections)", EXIT_BAD_INPUT)
    if model == "mf1989" and out is not None and out.suffix.lower() == ".tir":
        raise fail("mf1989 coefficients are not a .tir model: use --report .json",
                   EXIT_BAD_INPUT)
    if strategy not in ("staged", "joint"):
        raise fail(f"--strategy {strategy!r}: staged or joint", EXIT_BAD_INPUT)
    noise_ab = {}
    for item in noise or ():
        ch, _, val = item.partition("=")
        try:
            parts = [float(v) for v in val.split(",")]
            if not 1 <= len(parts) <= 2:
                raise ValueError
        except ValueError:
            raise fail(f"--noise {item!r}: CH=a or CH=a,b (e.g. FY=20,0.01)",
                       EXIT_BAD_INPUT) from None
        ch = ch.strip().upper()
        scale = 1000.0 if ch.startswith("M") else 1.0   # N·m → N·mm, b is relative
        noise_ab[ch] = (parts[0] * scale, parts[1] if len(parts) == 2 else 0.0)
    check_output(out, suffixes=None if model == "mf1989" else (".tir",), what="fitted model")
    check_output(report, suffixes=(".json", ".csv", ".html"), what="report")
    check_output(figures, what="figures folder", directory=True)
    c = console(markup=False)
    with cli_errors():
        enable_x64()
        if model != "mf1989":
            tir, m0 = _load(start)
            want = {"mf61": "6.1", "mf62": "6.2", "mf52": "5.2"}[model]
            if m0.version != want:
                raise fail(f"--model {model} but {start} is MF {m0.version} (FITTYP "
                           f"{tir.fittyp}); use --model mf{m0.version.replace('.', '')}",
                           EXIT_BAD_INPUT)
        if model == "mf1989":
            m0, tir = MagicFormula89.from_values(F.MF1989_START), None
        from diffsusp.tyre.input_tables import read_tyre_table

        with warnings.catch_warnings(record=True) as rec:
            warnings.simplefilter("always")
            bench, left = F.model_bench_data(m0, read_tyre_table(data, "bench table"))
            if left:   # fit what the model has
                warn(f"{data}: {', '.join(left)} not fitted: {model} has no such output "
                     f"(fitting {', '.join(bench.channels)})")
        for w in rec:
            warn(w.message)
        unknown = [ch for ch in noise_ab if ch not in bench.channels]
        if unknown:
            raise fail(f"--noise for {', '.join(unknown)}: not a channel of the data "
                       f"({', '.join(bench.channels)})", EXIT_BAD_INPUT)
        c.print(f"fitting {', '.join(mode or m0.default_groups(bench.channels))} "
                f"({bench.n} points, {strategy}) ...")
        groups, fitted, rep = F.fit_groups(m0, bench, mode, free=free or (), tir=tir,
                                           where=f"{data}: ", loss=loss,
                                           noise=noise_ab or None, strategy=strategy,
                                           max_steps=max_steps)
        c.print(rep.table(), highlight=False)
        converged = bool(rep.converged)
        if not converged:   # never a success, the model only on request
            warn(f"the fit did NOT converge in {rep.steps} steps (max {max_steps} per stage): "
                 "the coefficients are not a minimum; "
                 + ("the fitted .tir is written, marked NOT CONVERGED" if out is not None and
                    keep_unconverged else "the fitted model is not written"
                    + (" (--keep-unconverged writes it, marked)" if out is not None else "")))
        if out is not None and tir is not None and (converged or keep_unconverged):
            from diffsusp.io.tir import write_tir

            written = fitted.to_tir(tir, ranges=True)   # the validity ranges: the data's
            write_tir(written, out, header=None if converged else
                      f"$ NOT CONVERGED: diffsusp tyre fit stopped after {rep.steps} steps "
                      "without converging; these coefficients are not a fit\n")
            c.print(f"fitted model written to {out} (validity ranges: the data's)"
                    + ("" if converged else " — NOT CONVERGED"))
        if report is not None and report.suffix.lower() == ".json":
            report.write_text(json.dumps({"+".join(groups): rep.to_dict()}, indent=2) + "\n")
        elif report is not None:   # the shared writers: the same statuses as the table
            rep.write(report)
        if figures is not None:
            F.plot_fit(fitted, bench, folder=figures)
            c.print(f"figures written to {figures}")
        if not converged or (rep.consistency is not None and not rep.consistency.consistent):
            raise typer.Exit(3)
