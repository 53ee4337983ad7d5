"""`diffsusp demo`: the thesis half axle (`pseudo_mcpherson`) under the 13 load cases of Table 5-1,
solved in one batched, compiled call; prints a table and the timing.
"""

import time

import typer
from rich import box
from rich.table import Table

from .common import EXIT_NOT_CONVERGED, app, console, enable_x64


def wheel_angles(spin_axis):
    """Steer (rotation of the spin axis about global +z) and inclination of the spin axis out of
    the ground plane, in radians, from the spin axis (n, 3) in the global frame."""
    import jax.numpy as jnp

    steer = jnp.arctan2(spin_axis[..., 0], -spin_axis[..., 1])
    incline = jnp.arcsin(spin_axis[..., 2] / jnp.linalg.norm(spin_axis, axis=-1))
    return steer, incline


@app.command()
def demo():
    """Solve the 13 thesis load cases (Table 5-1) on the pseudo-McPherson half axle."""
    enable_x64()
    import jax
    import numpy as np

    import diffsusp
    from diffsusp.models import TABLE_5_1, pseudo_mcpherson, thesis_load_cases

    out = console()
    with out.status("building the model and compiling the solver..."):
        mech = pseudo_mcpherson()
        loads = thesis_load_cases(mech)
        t0 = time.perf_counter()
        sol = diffsusp.solve_statics(mech, loads, throw=False)
        jax.block_until_ready(sol.q)
        compile_time = time.perf_counter() - t0
    t0 = time.perf_counter()
    repeats = 20
    for _ in range(repeats):
        sol = diffsusp.solve_statics(mech, loads, throw=False)
    jax.block_until_ready(sol.q)
    solve_time = (time.perf_counter() - t0) / repeats

    wc = mech.markers.index("wheel_centre")
    pos, rot = diffsusp.marker_poses(mech, sol.q)
    pos0, rot0 = mech.markers.position[wc], mech.markers.orientation[wc]
    steer, incline = wheel_angles(rot[:, wc, :, 2])
    steer0, incline0 = wheel_angles(rot0[:, 2])
    disp = np.asarray(pos[:, wc] - pos0)
    d_steer = np.degrees(np.asarray(steer - steer0))
    d_incline = np.degrees(np.asarray(incline - incline0))

    table = Table(title=f"{mech.name}: thesis load cases (Table 5-1) at the contact patch",
                  box=box.SIMPLE_HEAD)
    for col in ("case", "Fz N", "Fy N", "Fx N", "Δx mm", "Δy mm", "Δz mm", "steer°", "incl°",
                "iter", "status"):
        table.add_column(col, justify="right", no_wrap=True)
    status_text = {0: "ok", 1: "max steps", 2: "non-finite"}
    for c in range(len(TABLE_5_1)):
        fv, fl, fx = TABLE_5_1[c]
        table.add_row(
            str(c + 1), f"{fv:.0f}", f"{fl:.0f}", f"{fx:.0f}",
            *(f"{v:+.2f}" for v in disp[c]), f"{d_steer[c]:+.3f}", f"{d_incline[c]:+.3f}",
            str(int(sol.iterations[c])), status_text[int(sol.status[c])],
        )
    out.print(table)
    out.print(
        "Fz, Fy, Fx: vertical, lateral, longitudinal force at the contact patch (global axes). "
        "Δ: wheel-centre displacement from design; steer°: rotation of the spin axis about "
        "global +z; incl°: change of the spin axis's inclination to the ground plane "
        "(Adams/Car frame: x rearward, y right, z up; left wheel)."
    )
    out.print(
        f"compile + first solve: {compile_time:.2f} s; 13 cases: {solve_time * 1e3:.2f} ms "
        f"({len(TABLE_5_1) / solve_time:.0f} equilibria/s)"
    )
    if not bool(np.all(np.asarray(sol.status) == 0)):
        raise typer.Exit(code=EXIT_NOT_CONVERGED)

