"""Shared test helpers: pytree comparison and finite-difference derivatives,
and the status column of a printed identification table (docs/guides/trust.md).

Import from a test file as `from helpers import tree_allclose, central_fd, fd_jvp` (pytest puts
`tests/` on `sys.path`).
"""

import jax
import jax.numpy as jnp
import numpy as np


def tree_allclose(actual, desired, *, rtol=1e-7, atol=0.0, err_msg=""):
    """Assert that two pytrees have the same structure and every pair of array leaves is close
    (`numpy.testing.assert_allclose`); a failure names the leaf's path."""
    with_path = jax.tree_util.tree_leaves_with_path(actual)
    desired_leaves, desired_def = jax.tree_util.tree_flatten(desired)
    assert jax.tree_util.tree_structure(actual) == desired_def, (
        f"{err_msg} pytree structures differ: {jax.tree_util.tree_structure(actual)} vs "
        f"{desired_def}")
    for (path, a), d in zip(with_path, desired_leaves, strict=True):
        np.testing.assert_allclose(np.asarray(a), np.asarray(d), rtol=rtol, atol=atol,
                                   err_msg=f"{err_msg} leaf {jax.tree_util.keystr(path)}")


def fd_jvp(fn, x, v, h):
    """Central finite-difference JVP of `fn` at the pytree `x` in the direction `v` (a pytree
    like `x`): (fn(x + h v) − fn(x − h v)) / 2h, leaf by leaf (second-order accurate)."""
    plus = fn(jax.tree.map(lambda a, b: a + h * b, x, v))
    minus = fn(jax.tree.map(lambda a, b: a - h * b, x, v))
    return jax.tree.map(lambda p, m: (p - m) / (2 * h), plus, minus)


def central_fd(fn, x, h):
    """Jacobian of the array function `fn` at the array `x` by central differences, one column
    per element of `x` (in C order) stacked on the last axis: shape `fn(x).shape + (x.size,)`."""
    x = jnp.asarray(x)
    cols = [fd_jvp(fn, x, jnp.zeros(x.size).at[k].set(1.0).reshape(x.shape), h)
            for k in range(x.size)]
    return jnp.stack(cols, axis=-1)


def table_statuses(text: str, names) -> dict:
    """Parameter → status of a printed identification table (`format_table`): on each row
    whose first word is one of `names`, the `STATUSES` entry that starts first in the line."""
    from diffsusp.identify.report import STATUSES

    out = {}
    for line in text.splitlines():
        words = line.split()
        if words and words[0] in names:
            found = sorted((line.index(s), s) for s in STATUSES if s in line)
            assert found, line
            out[words[0]] = found[0][1]  # the status cell starts with the status
    return out


def noisy_campaign(seed: int):
    """The shipped noise-free steering-feel campaign (tests/data/tyre_flat_trac_campaign.npz,
    made by tests/test_tyre_bench.py) cut to its 3 Hz slip sines (even segments), load sines
    and ramps, with the bench's noise (6 N on F_y, 600 N·mm on M_z) drawn from `seed`; returns
    (table, rng) so a caller can go on drawing from the same generator."""
    import pathlib

    z = np.load(pathlib.Path(__file__).parent / "data" / "tyre_flat_trac_campaign.npz")
    table = {c: np.asarray(z[c], float) for c in z.files}
    n = len(table["FY"]) // 24  # 24 segments of 200 samples
    keep = [k for k in range(24) if k >= 16 or k % 2 == 0]
    rows = np.concatenate([np.arange(k * n, (k + 1) * n) for k in keep])
    table = {c: v[rows] for c, v in table.items()}
    table["t"] = np.tile(np.arange(n) / 200.0, len(keep))
    table["segment"] = np.repeat(np.arange(len(keep), dtype=float), n)
    rng = np.random.default_rng(seed)
    table["FY"] = table["FY"] + 6.0 * rng.standard_normal(len(rows))
    table["MZ"] = table["MZ"] + 600.0 * rng.standard_normal(len(rows))
    return table, rng
