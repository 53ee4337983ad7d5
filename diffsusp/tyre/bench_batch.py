"""The bench identification of a campaign of many tyres in one compiled program (spec:
tyre §3.3–3.5, §8 items 4 and 8).

`identify_many` runs, for the F_y of every data set (a Flat Trac table of one tyre at one
pressure, or its `bench.condition`), the identification of `bench.identify_output` — the
conditioning, the structure search and the two-step estimate of K_y — traced in JAX and mapped
over the stacked data sets with `lax.map`, so a campaign of 4 tyres × 3 pressures is one
program.

**Why `lax.map` and not `jax.vmap`:** the search is vmappable (fixed shapes, `while_loop`s),
but under `jax.vmap` jaxlib 0.10's CPU LAPACK kernels (QR, triangular solves) run batched and
fan out over XLA's intra-op thread pool from inside a pool thread: on the 2-core machine the
vmapped program deadlocked (every pool thread parked in `jax::ParallelBatchMap`, no CPU used;
in 5 of 6 runs). Under `vmap` the noise-model update and the phase branch (`lax.cond`) also
become selects that evaluate both branches for every set at every step (the run that
finished: 5.9 s of CPU for 2 sets with its compile, `lax.map` 2.1 s). `lax.map` runs one
set at a time inside the program: one set's memory, real branches, unbatched LAPACK.

**The structure search** is the library's (`bench.structure_search`), step by step: the
guaranteed least squares decide what the data determine (the kept columns by the pivoted
selection of `lsq` on the R-factor of [W, −y], refitted after every removal); a coefficient is
removed when its σ % > `sigma_pct_threshold` **and** the F-test says its removal does not raise
the residual beyond the noise: (x_i/σ_i)² < χ²₁ quantile of `significance`, σ the sandwich of
the least squares under the filtered noise model (`bench.NoiseGram`, S = Wᵀ·Σ·W recomputed when
the relaxation gain moves by > 5 %, the noise level of the data from above the cut-off); the
largest σ % first. Each refit is the masked QR of the scaled R-factor (the removed columns
pinned by identity rows, `lsq.core.masked_solve`): fixed shapes, no host round trip. With the
library's final pass under the instrumental-variable estimator
(`identify_output(final_pass=True)`, the default), the traced search runs it too (its σ from
`bench.two_step`, step 1 at the data's noise level).

**The behaviour rules** (`bench.structure_rules`: deformation load polynomials keep their
sign, Table 6 counts per domain) are Python checks on the coefficient values; they run on the host
after the program, on the state at which the library would run them (the end of each phase):
a set for which a rule would remove a coefficient (one of the coefficients that mend the fault
fails the F-test) is sent through the library's exact search (`bench.identify_output`), and its
report is the library's; for the other sets every fault is excused (the data support it), as
the library finds, and the traced result stands. So every set's structure is the library's
(with the default σ % threshold, ≤ 100/√crit = 30.4 %, every coefficient a phase keeps passes
the F-test, so the rules can only excuse: no set takes the exact path). One caveat: where the
kept columns are nearly collinear (condition number ~1e11 after the n·ε selection of `lsq`:
the 24-segment test campaign), the library's first removals rank coefficients whose σ % of
1e5–1e7 and values are rounding noise, and a different rounding (the program's masked QR
against LAPACK's QR of the kept columns) takes another path: a different final structure.
On the 54-segment test campaign and the benchmark's 12 sets the structures are identical and
K_y agrees to 1e-12.

**Step 2** (K_y⁻¹ by `bench.two_step`: instrumental variables, σ of the joint model under the
noise model) runs in the same program on the final structure, the removed columns held at zero
(`two_step` on all p columns; its traced inverse leaves the exactly-null rows and columns of
its p×p normal matrices alone).

The reports are `bench.OutputReport`s (`fit` None: no `lsq.Fit` object is built per set; the
log is in `removed`, name → reason, in the library's words; `not_identifiable` names the same
coefficients with a shorter reason: "not identifiable", without the `lsq` relation), one per
data set, in `CampaignResult.reports`. M_z (`mz=True`) is identified per set by the library
(`bench.identify_output`, instrumented by the batched F_y): its search is F_y's plus the
coupling-term treatment of M_z, not traced here.
"""

import dataclasses
from collections.abc import Sequence

import jax
import jax.numpy as jnp
import numpy as np
import scipy.stats

from ..compilation import CPU_OPTIONS
from ..errors import InputError, ModelError
from ..lsq import core
from . import bench, relaxation
from .bench_condition import check_table, kept_rows, kinematics
from .bench_synthetic import segment_inputs, synthetic_flat_trac
from .poly import STRUCTURES, PolynomialModel, parse_name, regressor_model

__all__ = ["identify_many", "CampaignResult", "search_program", "BenchScenario"]


@dataclasses.dataclass
class CampaignResult:
    """`identify_many`'s result: `reports` (one `bench.OutputReport` per data set, in order),
    `exact` (index → why the set went through the library's exact search), `kept` (sets × p
    bool: the final structure, over `names`), `names` (the LIP model's coefficients),
    `search_steps` (removals per set in the traced search), `gram_updates` (the noise-model
    Gram S recomputed, per set), `program_seconds`, `program_cpu_seconds`
    (wall and CPU time of the compiled program's run, compile included on the first call),
    `mz_reports` (M_z's `bench.OutputReport`s with `mz=True`, else None)."""

    reports: list
    exact: dict
    kept: np.ndarray
    names: tuple
    search_steps: np.ndarray
    gram_updates: np.ndarray
    program_seconds: float
    program_cpu_seconds: float
    mz_reports: list | None = None

    @property
    def stiffness(self) -> np.ndarray:
        return np.array([r.stiffness for r in self.reports])

    @property
    def compliance_sigma(self) -> np.ndarray:
        return np.array([r.compliance_sigma for r in self.reports])

    def report_set(self) -> bench.ReportSet:
        """The F_y reports (then M_z's, when identified) as one `bench.ReportSet`, labelled
        "Fy set i" / "Mz set i", with the campaign's own fields (the structure over `names`,
        search steps, program times) at the top of its JSON."""
        reports = list(self.reports) + list(self.mz_reports or ())
        labels = [f"Fy set {i}" for i in range(len(self.reports))] + [
            f"Mz set {i}" for i in range(len(self.mz_reports or ()))]
        extra = {"names": list(self.names), "kept": np.asarray(self.kept).tolist(),
                 "exact": {str(k): v for k, v in self.exact.items()},
                 "search_steps": np.asarray(self.search_steps).tolist(),
                 "gram_updates": np.asarray(self.gram_updates).tolist(),
                 "program_seconds": self.program_seconds,
                 "program_cpu_seconds": self.program_cpu_seconds}
        return bench.ReportSet(tuple(reports), labels, extra)

    def rows(self) -> list[dict]:
        """One row per data set and parameter (`report_set().rows()`)."""
        return self.report_set().rows()

    def summary(self) -> dict:
        return self.report_set().summary()

    def to_json(self, **kwargs) -> str:
        return self.report_set().to_json(**kwargs)

    def write(self, path) -> None:
        """.csv or .json by suffix (`bench.ReportSet.write`)."""
        self.report_set().write(path)


# --------------------------------------------------------------------------------------------
# The traced search (one data set)


def _search(W, y, gram, H, X, L, Dp, fydot, omega, Dm, dt, *, names, fixed0, crit, threshold,
            var, final_pass, profile=None):
    """The structure search of `bench.structure_search` without the behaviour rules, traced
    (one data set; fixed shapes). Returns a dict of arrays (see `search_program`)."""
    n, p = W.shape
    masks = bench.block_masks(names)
    dtype = W.dtype
    R = core.qr_r(core.augmented(W, y))
    A_sel, _, tol = core.scaled_problem(R, jnp.asarray(n, dtype), jnp.asarray(0.0, dtype))
    sc = jnp.linalg.norm(W, axis=0)
    sc = jnp.where(sc > 0, sc, 1.0)
    Rw, z = R[:p, :p] / sc, -R[:p, p]
    zeros = jnp.zeros(p, dtype)
    s = X.shape[0]
    y_seg = y.reshape(s, -1)

    def two_step(active, **kw):
        m = active.astype(dtype)
        return bench.two_step(jnp, X * m, L * m, Dp * m, fydot, y_seg, H, Dm, omega,
                              dt, is_ly=masks[0], is_pneu=masks[1], is_p2=masks[2],
                              profile=profile, **kw)

    def least_squares(active, S, g_ref, have_S):
        xs, cov_unit, _ = core.masked_solve(Rw, z, active, zeros)  # cov_unit: G_A⁻¹
        b = jnp.where(active, xs / sc, 0.0)
        g = gram.gain(b)
        moved = jnp.linalg.norm(g - g_ref) > 0.05 * jnp.linalg.norm(g_ref)
        update = ~have_S | moved
        S, g_ref = jax.lax.cond(update, lambda: (gram(b) / jnp.outer(sc, sc), g),
                                lambda: (S, g_ref))
        cov = cov_unit @ S @ cov_unit
        sig = jnp.where(active, jnp.sqrt(jnp.abs(jnp.diag(cov))) / sc, 0.0)
        return b, sig, S, g_ref, update

    final_keys = ("x", "sigma", "compliance", "compliance_sigma", "sigma_step2", "noise_sigma",
                  "fydot_hat", "residual")

    def iv(active):
        """The final pass's estimate: `two_step` (steps 1 and 2, the σ from the residual's
        noise level: the report's) and its step-1 σ at the data's noise level (the search's:
        F_y's noise model has one source, so σ scales with the noise σ)."""
        res = two_step(active)
        ratio = jnp.sqrt(var) / jnp.where(res["noise_sigma"] > 0, res["noise_sigma"], 1.0)
        return (jnp.where(active, res["x"], 0.0), jnp.where(active, res["sigma"] * ratio, 0.0),
                {k: res[k] for k in final_keys})

    def stats(b, sig, active):
        with jax.numpy_dtype_promotion("standard"):
            pct = jnp.nan_to_num(100.0 * sig / jnp.abs(b), nan=jnp.inf, posinf=jnp.inf)
            stat = jnp.nan_to_num((b / sig) ** 2, nan=0.0)
        return jnp.where(active, pct, 0.0), jnp.where(active, stat, 0.0)

    def select(fixed):
        return core.select(A_sel, ~fixed, tol, True)

    def aliases(fixed, before):
        """`bench.aliased_columns`: the columns a removal brought back (kept after, dropped for rank
        before), held at 0 with it when that drops the number of estimable ones by one."""
        n_active = jnp.sum(before)

        def more(c):
            return ~c[3] & (jnp.sum(c[2]) >= n_active)

        def chain(c):
            trial, found, after, _ = c
            back = after & ~before & ~trial
            none = ~jnp.any(back)
            new_after = select(trial | back)
            return (jnp.where(none, trial, trial | back), jnp.where(none, found, found | back),
                    jnp.where(none, after, new_after), none)

        first = select(fixed)
        _, found, after, stop = jax.lax.while_loop(
            more, chain, (fixed, jnp.zeros_like(fixed), first, jnp.asarray(False)))
        ok = ~stop & (jnp.sum(after) == n_active - 1)
        # (the aliases; the kept columns of the next step, which need no second selection)
        return found & ok, jnp.where(ok, after, first)

    g0 = gram.gain(zeros)
    # the model of every column the data can estimate, before any removal (`bench`'s `full`)
    active0 = select(jnp.asarray(fixed0))
    full_x, full_sigma, *_ = least_squares(active0, jnp.zeros((p, p), dtype), g0,
                                           jnp.asarray(False))
    state0 = dict(fixed=jnp.asarray(fixed0), go=jnp.asarray(True), steps=jnp.asarray(0),
                  phase=jnp.asarray(0),
                  S=jnp.zeros((p, p), dtype), g_ref=g0, have_S=jnp.asarray(False),
                  order=jnp.full(p, -1), order_pct=jnp.zeros(p, dtype),
                  order_stat=jnp.zeros(p, dtype), order_phase=jnp.zeros(p, int),
                  alias_step=jnp.full(p, -1),
                  x=zeros, sigma=zeros, stat=zeros, active=jnp.zeros(p, bool),
                  ls_x=zeros, ls_stat=zeros, ls_active=jnp.zeros(p, bool),
                  ls_done=jnp.asarray(False), next=select(jnp.asarray(fixed0)),
                  gram_updates=jnp.asarray(0),
                  final=dict(x=zeros, sigma=zeros, compliance=zeros[0], compliance_sigma=zeros[0],
                             sigma_step2=zeros[0], noise_sigma=zeros[0],
                             fydot_hat=jnp.zeros_like(fydot), residual=jnp.zeros_like(y)))

    def body(st):
        st = dict(st)
        active = st["next"]
        if final_pass is None:
            b, sig, S, g_ref, update = least_squares(active, st["S"], st["g_ref"],
                                                     st["have_S"])
        else:
            def ls_branch():
                return least_squares(active, st["S"], st["g_ref"], st["have_S"])

            def iv_branch():
                b, sig, fin = iv(active)
                return b, sig, st["S"], st["g_ref"], jnp.asarray(False), fin

            def ls_final():
                return (*ls_branch(), st["final"])
            b, sig, S, g_ref, update, st["final"] = jax.lax.cond(st["phase"] == 0, ls_final,
                                                                 iv_branch)
        st.update(S=S, g_ref=g_ref, have_S=st["have_S"] | (st["phase"] == 0),
                  gram_updates=st["gram_updates"] + update)
        pct, stat = stats(b, sig, active)
        removable = active & (stat < crit) & (pct > threshold)
        k = jnp.argmax(jnp.where(removable, pct, -jnp.inf))
        hit = jnp.any(removable)
        st["order"] = st["order"].at[st["steps"]].set(jnp.where(hit, k, -1))
        st["order_pct"] = st["order_pct"].at[st["steps"]].set(pct[k])
        st["order_stat"] = st["order_stat"].at[st["steps"]].set(stat[k])
        st["order_phase"] = st["order_phase"].at[st["steps"]].set(st["phase"])
        fixed = st["fixed"].at[k].set(st["fixed"][k] | hit)
        al, st["next"] = aliases(fixed, active)
        st["alias_step"] = jnp.where(al, st["steps"], st["alias_step"])
        fixed = fixed | al
        st["fixed"] = fixed
        st["steps"] = st["steps"] + hit
        st.update(x=b, sigma=sig, stat=stat, active=active)
        # the end of a phase: the least-squares phase hands over to the final one
        to_iv = ~hit & (st["phase"] == 0) & (final_pass is not None)
        st["ls_x"] = jnp.where(~hit & (st["phase"] == 0), b, st["ls_x"])
        st["ls_stat"] = jnp.where(~hit & (st["phase"] == 0), stat, st["ls_stat"])
        st["ls_active"] = jnp.where(~hit & (st["phase"] == 0), active, st["ls_active"])
        st["ls_done"] = st["ls_done"] | (~hit & (st["phase"] == 0))
        st["phase"] = jnp.where(to_iv, 1, st["phase"])
        st["go"] = (hit | to_iv) & jnp.any(active)
        return st

    st = jax.lax.while_loop(lambda st: st["go"] & (st["steps"] < p), body, state0)
    # the final estimate: the final pass's last one (on the final structure), or step 2 now
    res = st["final"] if final_pass is not None else two_step(st["active"])
    # the consistency's whitened residual, once, on the final structure
    white = two_step(st["active"], check_var=var)["whitened"]
    out = {k: st[k] for k in ("fixed", "active", "order", "order_pct", "order_stat",
                              "order_phase", "alias_step", "x", "sigma", "stat", "ls_x", "ls_stat",
                              "ls_active", "ls_done", "steps", "gram_updates")}
    out["kept"] = select(st["fixed"])
    out["diag"] = jnp.abs(jnp.diagonal(R)[:p])
    out.update(final_x=res["x"], final_sigma=res["sigma"], compliance=res["compliance"],
               compliance_sigma=res["compliance_sigma"], sigma_step2=res["sigma_step2"],
               noise_sigma=res["noise_sigma"], fydot_hat=res["fydot_hat"],
               residual=res["residual"], whitened=white, full_x=full_x,
               full_sigma=full_sigma, full_active=active0)
    return out


def _condition_traced(cols, H, Dm, E, E_noise, rolling_radius, rows):
    """`bench.condition` of one data set, traced: the deformation inputs (full rate), the
    filtered F_y and M_z at the kept rows, their noise levels from above the cut-off, F_y's
    relative noise profile (`noise_w_fy`) and outliers replaced (`bench.noise_model`)."""
    cols = dict(cols)
    m = E.shape[0]
    inner = np.zeros(m, bool)
    inner[int(rows[0]):int(rows[-1]) + 1] = True
    Fm = jnp.eye(m) - E
    noise, profile = {}, {}
    for c, u in (("FY", 1.0), ("MZ", 1e-3)):
        cols[c], level, profile[c], _, _ = bench.noise_model(cols[c], E, Fm, inner,
                                                              E_noise=E_noise,
                                                              margin=int(rows[0]) // 2)
        noise[c] = level * u
    samples = kinematics(cols, Dm, rolling_radius)
    samples["noise_w_fy"] = profile["FY"]
    fz = samples["fz"][:, rows]
    return samples, (cols["FY"] @ H.T).ravel(), (cols["MZ"] @ H.T).ravel() * 1e-3, noise, \
        jnp.stack([jnp.min(fz), jnp.max(fz)])


def search_program(degrees, *, rolling_radius=0.294, rows, dt, final_pass=None, fixed=(),
                   batch="map", from_tables=True):
    """The traced F_y identification of many data sets as one function (jit it): from stacked
    bench channels (`from_tables`: dict channel → (sets, segments, samples), then the filter's
    rows H, the difference matrix Dm, E = [I − F, `bench.noise_band`] (2, m, m)) or stacked
    conditioned data (samples dict
    (sets, segments, samples), y (sets, n), M_z (sets, n), noise (sets, 2): FY, MZ; F_z range
    (sets, 2), then H, Dm), and last `params` = [σ % threshold (inf: none), χ²₁ critical
    value]. `batch`: "map" (`lax.map`, one set at a time in the program: the memory of one
    set, the noise-model update a real branch; see the module docstring for `jax.vmap`) or
    "loop" (the one-set function, to call per set).

    Per set: the search's final mask `fixed`, `active`, `kept`, the removal order `order`
    (index, −1 padded) with the σ % and F statistic at removal (`order_pct`, `order_stat`,
    `order_phase` 0 least squares, 1 final pass; `alias_step`: the step that held an alias),
    the last step's `x`, `sigma`, `stat`, those at the end of the least-squares phase
    (`ls_x`, `ls_stat`, `ls_active`), and the two-step estimate on the final structure
    (`final_x`, `final_sigma`, `compliance`, `compliance_sigma`, `sigma_step2`,
    `noise_sigma`, `fydot_hat`); with the noise levels (FY, MZ) and the F_z range."""
    lip = regressor_model("Fy", degrees, ly=True)
    names = lip.names
    parts = bench.parts_fn(lip)
    fixed0 = np.zeros(len(names), bool)
    for nm in fixed:
        if nm not in names:
            raise InputError(f"fixed: {nm!r} is not a coefficient of the Fy model")
        fixed0[names.index(nm)] = True

    def identify(samples, y, noise, H, Dm, params):
        X, L, Dp = parts(samples)
        fydot = samples["fydot_w"]
        W = jnp.einsum("rm,smp->srp", H, X + L * fydot[..., None]).reshape(-1, len(names))
        var = noise[0] ** 2
        profile = samples.get("noise_w_fy")
        gram = bench.NoiseGram(W, L, bench.block_masks(names)[0], H, Dm, samples["omega"], var,
                                profile=profile)
        return _search(W, y, gram, H, X, L, Dp, fydot, samples["omega"], Dm, dt, names=names,
                       fixed0=fixed0, crit=params[1], threshold=params[0], var=var,
                       final_pass=final_pass, profile=profile)

    def one_table(cols, H, Dm, E, params):
        samples, fy, _, noise, fz_range = _condition_traced(cols, H, Dm, E[0], E[1],
                                                            rolling_radius,
                                                            rows)
        noise = jnp.stack([noise["FY"], noise["MZ"]])
        return identify(samples, fy, noise, H, Dm, params), noise, fz_range

    def one_cond(samples, fy, noise, fz_range, H, Dm, params):
        return identify(samples, fy, noise, H, Dm, params), noise, fz_range

    one = one_table if from_tables else one_cond
    n_shared = 4 if from_tables else 3  # (H, Dm[, E], params): the same for every set
    if batch == "loop":
        return one
    if batch == "map":
        def run(*args):
            shared = args[-n_shared:]
            return jax.lax.map(lambda d: one(*d, *shared), args[:-n_shared])
        return run
    raise InputError(f"batch {batch!r}: 'map' or 'loop'")


# --------------------------------------------------------------------------------------------
# The campaign (host side)


_COMPILED: dict = {}


def _compiled(key, make, optimize):
    """One compiled program per configuration. `optimize` False: XLA's backend optimisation
    off (as `bench_condition.quick_jit`: the program compiles in a third of the time and runs a
    little slower; the right trade for one campaign), True: the default level (the benchmark)."""
    key = key + (optimize,)
    if key not in _COMPILED:
        options = {}
        if not optimize:
            options = {"xla_backend_optimization_level": 0}
            if jax.default_backend() == "cpu":
                options.update(CPU_OPTIONS)
        _COMPILED[key] = jax.jit(make(), compiler_options=options or None)
    return _COMPILED[key]


def _behaviour_removal(behaviour, names, active, x, stat, crit):
    """What the library's search does with the behaviour rules on a state where no
    coefficient fails the statistical test (`bench.structure_search`): returns (the
    coefficient a rule removes and the rule's key, or None; the faults excused)."""
    values = {names[i]: float(x[i]) for i in np.flatnonzero(active)}
    f_of = {names[i]: float(stat[i]) for i in np.flatnonzero(active)}
    excused: set = set()
    found = bench.behaviour_removal(behaviour, values, f_of, crit, excused)
    return found, sorted(excused)


def _stack_tables(tables, cutoff, decimate):
    checked = [check_table(t, cutoff) for t in tables]
    shapes = {(n, m, round(rate, 9)) for _, n, m, rate in checked}
    if len(shapes) != 1:
        raise InputError(f"identify_many: the data sets differ in shape (segments, samples, "
                         f"rate) {sorted(shapes)}; a batch needs equal ones (group them).")
    _, n_seg, m, rate = checked[0]
    cols = {c: np.stack([c_[c] for c_, *_ in checked]) for c in bench.REQUIRED
            if c not in ("t", "segment")}
    return cols, n_seg, m, rate


def identify_many(data: Sequence, *, structure: str = "just-necessary", degrees=None,
                  cutoff: float = 25.0, rolling_radius: float = 294.0,
                  decimate: int | None = None, sigma_pct_threshold: float | None = 10.0,
                  significance: float = 1e-3, ic_threshold: float = 0.0, rules: bool = True,
                  final_pass: bool = True, fixed=(), mz: bool = False, batch: str = "map",
                  optimize: bool = True) -> CampaignResult:
    """Identify F_y and K_{Fy,y} on many data sets (a campaign: tyres × pressures) in one
    compiled program, with the library's structure search and two-step estimate (see the
    module docstring; spec: tyre §3.3–3.5).

    **Arguments:** `data`: bench tables (column → array, `bench.REQUIRED`; conditioned in the
    program) or `bench.Conditioned` (from `bench.condition`), all of one shape (segments,
    samples, rate); `structure` ("just-necessary", "apriori") or `degrees` (F_y's);
    `cutoff`, `rolling_radius` [mm], `decimate` as `bench.condition` (tables only);
    `sigma_pct_threshold`, `significance`, `rules`, `fixed` (names held at 0) as
    `bench.identify_output`; `ic_threshold` > 0 (an IC rule: not traced) sends every set
    through the exact search; `final_pass`: the search's final pass under the instrumental-
    variable estimator (as `bench.identify_output`'s, default on); `mz`: also identify M_z,
    set by set by the library (`bench.identify_output` with the batched F_y report as its
    instrument; its M_z-specific search is not traced);
    `batch`: "map" (`lax.map`, default), "loop" (the one-set program called per set: the
    reference); `optimize`: XLA's backend optimisation (default; measured on 3 sets: 3.6×
    faster to run, 3.5× slower to compile; False for one-off runs and the tests).

    **Returns:** `CampaignResult`: per set a `bench.OutputReport` of F_y (the structure, x and
    σ of the final estimate, K_y and its σ, the removal log in `removed`), `exact` (the sets
    a behaviour rule sent through `bench.identify_output`, with the rule), `mz_reports`."""
    import time

    if structure not in STRUCTURES:
        raise InputError(f"structure {structure!r}: one of {', '.join(STRUCTURES)}")
    data = list(data)
    if not data:
        raise InputError("identify_many: no data sets")
    degrees = dict(degrees if degrees is not None else STRUCTURES[structure]["Fy"])
    fixed = tuple(fixed or ())
    final_pass = "after" if final_pass else None
    r_m = rolling_radius * 1e-3
    crit = float(scipy.stats.chi2.isf(significance, 1))
    conditioned = all(isinstance(d, bench.Conditioned) for d in data)
    if conditioned:
        c0 = data[0]
        if any(d.samples["fz"].shape != c0.samples["fz"].shape or d.dt != c0.dt
               or not np.array_equal(d.operator, c0.operator) for d in data):
            raise InputError("identify_many: the conditioned data sets differ in shape or "
                             "filter; a batch needs equal ones (group them).")
        rows, dt = np.asarray(c0.rows), c0.dt
        samples = {k: np.stack([np.asarray(d.samples[k]) for d in data]) for k in c0.samples}
        samples["noise_w_fy"] = np.stack([
            np.asarray((d.noise_profile or {}).get("FY", np.ones(d.samples["fz"].shape)))
            for d in data])
        args = (samples,
                np.stack([d.fy for d in data]),
                np.array([[d.noise["FY"], d.noise["MZ"]] for d in data]),
                np.array([[d.inputs["fz"].min(), d.inputs["fz"].max()] for d in data]),
                c0.operator, c0.difference)
    elif any(isinstance(d, bench.Conditioned) for d in data):
        raise InputError("identify_many: give tables or conditioned data, not both")
    else:
        cols, n_seg, m, rate = _stack_tables(data, cutoff, decimate)
        rows, _ = kept_rows(m, rate, cutoff, decimate, None)
        F = bench.filter_matrix(float(cutoff), float(rate), m, 4)
        dt = 1.0 / rate
        E_noise = bench.noise_band(rate, cutoff, m, 4)
        args = (cols, F[rows], bench.difference_matrix(m, dt), np.stack([np.eye(m) - F, E_noise]))
    params = np.array([np.inf if sigma_pct_threshold is None else sigma_pct_threshold, crit])
    args = args + (params,)
    n_shared = 3 if conditioned else 4
    key = (tuple(sorted(degrees.items())), r_m, tuple(rows.tolist()), dt, final_pass, fixed,
           batch, conditioned)

    def make():
        return search_program(degrees, rolling_radius=r_m, rows=rows, dt=dt,
                              final_pass=final_pass, fixed=fixed, batch=batch,
                              from_tables=not conditioned)
    program = _compiled(key, make, optimize)
    t0, c0 = time.perf_counter(), time.process_time()
    if batch == "loop":
        pieces = [program(*jax.tree_util.tree_map(lambda a, i=i: a[i], args[:-n_shared]),
                          *args[-n_shared:]) for i in range(len(data))]
        raw = jax.tree_util.tree_map(lambda *a: np.stack([np.asarray(v) for v in a]), *pieces)
    else:
        raw = jax.tree_util.tree_map(np.asarray, program(*args))
    seconds = (time.perf_counter() - t0, time.process_time() - c0)
    result, _, fz_range = raw
    # the host side: reports, the behaviour rules, the exact path for the sets they change
    names = regressor_model("Fy", degrees, ly=True).names
    reports, exact, conds = [], {}, {}

    def cond_of(i):
        if i not in conds:
            conds[i] = data[i] if conditioned else bench.condition(
                data[i], cutoff=cutoff, rolling_radius=rolling_radius, decimate=decimate)
        return conds[i]

    def gamma_of(i):  # the camber at the kept rows (`Conditioned.inputs["gamma"]`)
        return data[i].inputs["gamma"] if conditioned else cols["camber"][i][:, rows].ravel()

    options = {"final_pass": final_pass is not None}
    Dm_host = None if conditioned else bench.difference_matrix(m, dt)

    def unexcited_of(i):  # the inputs the set does not excite (not seen)
        if conditioned:
            return bench.unexcited_inputs(data[i])
        samples = kinematics({c: cols[c][i] for c in cols}, Dm_host, r_m)
        exc = {k: float(np.std(np.asarray(samples[k])[:, rows]))
               for k in ("kappa", "delta", "phi", "gamma", "pi_gamma_vx", "pi_gamma_bdot",
                         "pi_gamma2_bdot")}
        return {k: v for k, v in exc.items() if v < bench.UNEXCITED}

    def dof_of(i):  # the degrees of freedom of the noise level (the consistency's F law)
        if conditioned:
            return (data[i].noise_dof or {}).get("FY")
        inner = np.zeros(m, bool)
        inner[rows[0]:rows[-1] + 1] = True
        return bench.noise_dof(E_noise[inner], n_seg)
    for i in range(len(data)):
        r = {k: v[i] for k, v in result.items()}
        if not r["active"].any():
            raise InputError(f"data set {i}: the structure search removed every coefficient "
                             "of Fy: the data do not determine this output (no excitation?)")
        why, excused = None, []
        if ic_threshold > 0:
            why = f"ic_threshold {ic_threshold:g} (the IC rule is not traced)"
        elif rules:
            lo, hi = float(fz_range[i][0]), float(fz_range[i][1])
            behaviour = bench.behaviour_rules("Fy", (lo, hi), rolling_radius=r_m,
                                              well_excited_load=bench.load_well_excited(lo, hi))
            phases = [("x", "stat", "active")]
            # the rules at the end of each phase, as the library; with σ % ≤ 100/√crit
            # (30.4 % at 10⁻³) every coefficient a phase keeps passes the F-test (F =
            # (100/σ %)² ≥ crit, or it was kept for F ≥ crit): no rule can remove one, they
            # only excuse, and the final phase's excused faults are the report's
            if final_pass is not None and not (sigma_pct_threshold is not None
                                               and sigma_pct_threshold <= 100 / crit**0.5):
                phases.insert(0, ("ls_x", "ls_stat", "ls_active"))
            for xk, sk, ak in phases:
                found, excused = _behaviour_removal(behaviour, names, r[ak], r[xk], r[sk], crit)
                if found is not None:
                    why = (f"behaviour rule {found[1][0]!r} removes {found[0]} "
                           f"({'least-squares' if xk == 'ls_x' else 'final'} phase)")
                    break
        if why is None:
            reports.append(_report("Fy", degrees, names, r, excused, sigma_pct_threshold,
                                   crit, gamma_of(i), dof_of(i), fixed, unexcited_of(i)))
        else:
            exact[i] = why
            reports.append(bench.identify_output(
                cond_of(i), "Fy", degrees, sigma_pct_threshold=sigma_pct_threshold,
                significance=significance, ic_threshold=ic_threshold, fixed=list(fixed) or None,
                rolling_radius=r_m, rules=rules, **options))
    mz_reports = None
    if mz:
        mz_reports = [bench.identify_output(
            cond_of(i), "Mz", STRUCTURES[structure]["Mz"],
            sigma_pct_threshold=sigma_pct_threshold, significance=significance,
            ic_threshold=ic_threshold, rolling_radius=r_m, rules=rules, fy_report=reports[i],
            **options) for i in range(len(data))]
    kept = np.array([[n in r.reduced.names for n in names] for r in reports])
    return CampaignResult(reports, exact, kept, names, np.asarray(result["steps"]),
                          np.asarray(result["gram_updates"]), *seconds, mz_reports)


def _report(output, degrees, names, r, excused, threshold, crit, gamma, noise_dof=None,
            fixed=(), unexcited=None):
    """A `bench.OutputReport` from one set's traced result, with its consistency verdict
    (`bench.bench_consistency`)."""
    active = np.flatnonzero(r["active"])
    act = [names[i] for i in active]
    is_pneu = bench.block_masks(act)[1]
    reduced = bench.Coefficients(tuple(act), np.asarray(r["final_x"])[active],
                                 np.asarray(r["final_sigma"])[active])
    model = PolynomialModel.create(output, degrees, values={
        n: x for n, x, k in zip(act, reduced.x, is_pneu, strict=True) if k})
    removed = {}
    for t in range(int(r["steps"])):
        how = "instrumental variables" if r["order_phase"][t] == 1 else "noise model"
        candidate = names[int(r["order"][t])]
        reason = (f"sigma% {r['order_pct'][t]:.3g} > {threshold:g} ({how}), "
                  f"F {r['order_stat'][t]:.3g} < {crit:.3g}")
        removed[candidate] = reason
        for j in np.flatnonzero(r["alias_step"] == t):
            removed[names[j]] = (f"with {candidate}: the same direction on these data (a "
                                 f"combination of it and the kept columns; {reason})")
    not_ident = {n: ("not identifiable: no effect on the data" if r["diag"][i] == 0
                     else "not identifiable")
                 for i, n in enumerate(names) if not r["kept"][i] and not r["fixed"][i]}
    if hasattr(bench, "camber_powers"):  # as `identify_output`: powers of held camber levels
        for n, why in bench.camber_powers(names, gamma).items():
            if n not in act:
                removed.pop(n, None)
                not_ident[n] = why
    white = np.asarray(r["whitened"])
    n_par = int(np.sum(bench.block_masks(act)[1])) + 1
    consistency = bench.bench_consistency(white, n_par, None, "FY", output,
                                          noise_dof=noise_dof)
    held = tuple(n for n in fixed if n not in removed and n not in not_ident)
    return bench.OutputReport(output, None, reduced, model, float(r["compliance"]),
                              float(r["compliance_sigma"]), float(r["sigma_step2"]),
                              float(r["noise_sigma"]), removed, not_ident,
                              np.asarray(r["fydot_hat"]) if output == "Fy" else None,
                              list(excused), candidates=tuple(names), held_names=held,
                              consistency=consistency,
                              residual=np.asarray(r["residual"]).reshape(white.shape),
                              whitened=white, crit=crit,
                              full={names[i]: (float(r["full_x"][i]), float(r["full_sigma"][i]))
                                    for i in np.flatnonzero(r["full_active"])},
                              threshold=None if not np.isfinite(threshold or np.inf)
                              else threshold, unexcited=unexcited)


# --------------------------------------------------------------------------------------------
# Rehearsal of a bench campaign (the user's experiment, random truths)


@dataclasses.dataclass
class BenchScenario:
    """A rehearsal scenario of the bench identification (`diffsusp.identify.rehearse`'s
    contract; spec: tyre §3.3–3.5, §4.3): random tyres around the user's start model, the
    user's bench programme simulated through the state-space model (3-82…3-87,
    `bench.synthetic_flat_trac`), the bench's noise added, and the F_y identification run
    batched (`identify_many`: structure search, two-step K_y), one report per tyre.

    **Fields:** `fy`, `mz` the start polynomial models (`poly.PolynomialModel`, F_pneu; M_z
    only to simulate M_z), `k_fy`, `k_mz` [N/m] the start lateral stiffnesses; `segments`
    (`bench.Segments`: the programme), `duration` [s] per segment, `rate` [Hz]; the noise:
    `noise` channel → (a, b) with σ = a + b·|channel| (table units: N, N·mm; FX, FZ plain σ in
    N), `outliers` the fraction of F_y samples hit by a spike of ± `outlier_size` σ; the
    spread of the truths: every non-zero F_pneu coefficient × U(1 − `spread`, 1 + `spread`)
    (default ±20 %), K_y × log-uniform in `k_range` (default 0.5–2); a draw whose F_y is past
    its grip peak somewhere on the programme (∂Fy_pneu/∂δ′ ≥ 0: the simulation model is
    unstable) is drawn again; `degrees` the structure searched (default Table 10's),
    `significance`, `sigma_pct_threshold` as `identify_many`; `optimize` its compile option.

    `names`: every candidate coefficient of the searched F_y model (those absent from the
    truth are 0; the relaxation terms b_Fy_Ly_(i−1)_j = b_Fy_delta_i_j/K_y, (3-62)) and
    `K_Fy_y` [N/mm], as the reports name them."""

    fy: PolynomialModel
    mz: PolynomialModel
    k_fy: float
    k_mz: float
    segments: object
    duration: float = 1.0
    rate: float = 200.0
    noise: dict = dataclasses.field(default_factory=lambda: {
        "FY": (6.0, 0.0), "MZ": (600.0, 0.0), "FX": 3.0, "FZ": 3.0})
    outliers: float = 0.0
    outlier_size: float = 20.0
    spread: float = 0.2
    k_range: tuple = (0.5, 2.0)
    degrees: dict | None = None
    significance: float = 1e-3
    sigma_pct_threshold: float | None = 10.0
    optimize: bool = False

    method = "bench"

    def __post_init__(self):
        if self.degrees is None:
            self.degrees = dict(STRUCTURES["just-necessary"]["Fy"])
        if not 0 < self.spread < 1:
            raise InputError(f"spread {self.spread:g}: a relative spread in (0, 1)")
        lo, hi = self.k_range
        if not 0 < lo <= hi:
            raise InputError(f"k_range {self.k_range}: 0 < low <= high")
        unknown = [n for n, v in self.fy.values().items() if v and n not in self._lip.names]
        if unknown:
            raise InputError(f"the start model has terms {unknown} outside the searched "
                             f"degrees {self.degrees}; widen the degrees")

    @property
    def _lip(self):
        return regressor_model("Fy", self.degrees, ly=True)

    @property
    def names(self) -> tuple[str, ...]:
        return self._lip.names + ("K_Fy_y",)

    def _inputs(self):
        t = jnp.arange(int(round(self.duration * self.rate))) / self.rate
        u = jax.vmap(lambda s: jax.vmap(lambda tt: segment_inputs(s, tt))(t))(self.segments)
        return {k: np.asarray(v).ravel() for k, v in u.items()}

    def _model(self, row):
        values = {n: float(v) for n, v in zip(self.names, row, strict=True)
                  if n.startswith("b_Fy_") and "_Ly_" not in n and v != 0}
        return PolynomialModel.create("Fy", self.degrees, values=values)

    def draw(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """(n, p) random truths (see the class docstring), in the reports' units."""
        if n < 1:
            raise InputError(f"n = {n}: at least one truth")
        start = {k: v for k, v in self.fy.values().items() if v}
        u = self._inputs()
        lo, hi = np.log(self.k_range[0]), np.log(self.k_range[1])
        out = []
        tries = 0
        while len(out) < n:
            tries += 1
            if tries > 50 * n:
                raise InputError("the spread puts nearly every draw past the grip peak on "
                                 "this programme; lower the spread or the slip amplitudes")
            coef = {k: v * rng.uniform(1 - self.spread, 1 + self.spread)
                    for k, v in start.items()}
            k = self.k_fy * float(np.exp(rng.uniform(lo, hi)))
            row = np.zeros(len(self.names))
            for name, v in coef.items():
                row[self.names.index(name)] = v
                _, block, i, j = parse_name(name)
                if block == "delta" and i > 1:
                    row[self.names.index(f"b_Fy_Ly_{i - 1}_{j}")] = v / k
                elif block == "delta" and i == 1:
                    row[self.names.index(f"b_Fy_Ly_0_{j}")] = v / k
            row[-1] = k * 1e-3
            if np.max(np.asarray(relaxation.stability_margin(self._model(row), u))) >= 0:
                continue
            clean = self._clean(row)
            if all(np.all(np.isfinite(v)) for v in clean.values()):
                out.append(row)
        return np.array(out)

    def _clean(self, truth) -> dict:
        """The noise-free bench table of one truth (kept: `draw` checks it is finite, every
        simulated state within the model's range; `identify` adds the noise)."""
        key = np.asarray(truth, float).tobytes()
        cache = self.__dict__.setdefault("_tables", {})
        if key not in cache:
            try:
                cache[key] = synthetic_flat_trac(
                    self._model(truth), self.mz, k_fy=float(truth[-1]) * 1e3, k_mz=self.k_mz,
                    segments=self.segments, duration=self.duration, rate=self.rate,
                    noise={"FY": 0.0, "MZ": 0.0, "FX": 0.0, "FZ": 0.0})
            except ModelError:
                cache[key] = {"FY": np.array([np.nan])}
        return cache[key]

    def simulate(self, truth, rng: np.random.Generator) -> dict:
        """The bench table of one truth (`bench.synthetic_flat_trac`, noise-free), with the
        scenario's noise and outliers."""
        table = dict(self._clean(truth))
        if not all(np.all(np.isfinite(v)) for v in table.values()):
            raise InputError("this truth's simulation leaves the model's range (non-finite "
                             "forces); draw the truths with `draw`")
        for c in ("FY", "MZ", "FX", "FZ"):
            spec = self.noise.get(c, 0.0)
            a, b = spec if isinstance(spec, tuple | list) else (spec, 0.0)
            sigma = a + b * np.abs(table[c])
            table[c] = table[c] + sigma * rng.standard_normal(table[c].shape)
            if c == "FY" and self.outliers > 0:
                hit = rng.random(table[c].shape) < self.outliers
                table[c] = table[c] + hit * rng.choice([-1.0, 1.0], table[c].shape) \
                    * self.outlier_size * sigma
        return table

    def identify(self, truths, rng: np.random.Generator) -> list:
        """One `bench.OutputReport` of F_y per truth: the tables simulated, then
        `identify_many` on all of them (one compiled program)."""
        tables = [self.simulate(t, rng) for t in np.atleast_2d(truths)]
        self.__dict__["_tables"] = {}  # the noise-free tables are not needed any more
        res = identify_many(tables, degrees=self.degrees, significance=self.significance,
                            sigma_pct_threshold=self.sigma_pct_threshold,
                            optimize=self.optimize)
        return res.reports
