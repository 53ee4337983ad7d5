"""The `diffsusp` command (Typer's test runner)."""

from typer.testing import CliRunner

from diffsusp.cli import app


def test_demo_prints_the_thesis_table_and_writes_the_figures(tmp_path):
    result = CliRunner().invoke(app, ["demo", "--out", str(tmp_path)])
    assert result.exit_code == 0, result.output
    out = result.output
    assert "Table 5-1" in out
    # 13 rows, all converged, and the timing line.
    assert out.count(" ok") >= 13
    assert "equilibria/s" in out
    # The 4500 N case is the design position: no vertical displacement (to print precision).
    row3 = next(line.split() for line in out.splitlines() if line.split()[:2] == ["3", "4500"])
    assert abs(float(row3[6])) < 0.005  # Δz in mm
    assert row3[-1] == "ok"
    assert "bump_steer" in out and "wheel_rate" in out
    for stem in ("parallel_travel", "table_5_1"):
        for ext in ("png", "svg"):
            assert (tmp_path / f"{stem}.{ext}").stat().st_size > 10_000


def test_no_arguments_shows_help():
    result = CliRunner().invoke(app, [])
    assert "demo" in result.output


def test_every_verb_registers_one_way_and_loads_its_model_one_way(tmp_path):
    """The CLI's structure: every verb is a `<verb>_command` added by its module's
    `register(app)` (its --help works); no CLI module imports another's private name; every
    verb that takes a MODEL goes through the one loader (`cli.common.load_model_file`), so an
    unknown name is the same bad input (exit 2, the built-in models listed) for all of them.
    Nothing here compiles."""
    import ast
    import importlib
    import pathlib
    import sys

    import typer

    import diffsusp.cli
    from diffsusp.resolve import builtin_models
    from diffsusp.tyre import examples

    runner = CliRunner()
    leaves = []

    def walk(command, path):
        if getattr(command, "commands", None):
            for name, sub in command.commands.items():
                walk(sub, [*path, name])
        else:
            leaves.append((path, command.callback))

    walk(typer.main.get_command(app), [])
    assert len(leaves) >= 24, leaves  # 6 verbs, identify 5, fleet 6, tyre 7
    for path, callback in leaves:
        assert callback.__name__.endswith("_command"), (path, callback.__name__)
        module = sys.modules[callback.__module__]
        assert module.__name__.startswith("diffsusp.cli.") and callable(module.register), path
        result = runner.invoke(app, [*path, "--help"])
        assert result.exit_code == 0 and "Usage" in result.output, (path, result.output)

    folder = pathlib.Path(diffsusp.cli.__file__).parent
    private = []
    for file in sorted(folder.glob("*.py")):
        for node in ast.walk(ast.parse(file.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom) and (node.level or (node.module or "").startswith(
                    "diffsusp")):
                private += [f"{file.name}: {a.name}" for a in node.names
                            if a.name.startswith("_") and not a.name.startswith("__")]
    assert not private, private
    assert importlib.import_module("diffsusp.cli.common").load_model_file

    loads = tmp_path / "loads.csv"
    loads.write_text("centre.fx [N]\n10\n")
    tir = next(examples.DATA.glob("*.tir"))
    verbs = [["kc", "no_such_model"], ["sensitivity", "no_such_model"],
             ["info", "no_such_model"],
             ["simulate", "no_such_model", "-l", str(loads), "-o", str(tmp_path / "r.csv")],
             ["rehearse", "direct", "no_such_model"],
             ["tyre", "rig", str(tir), "--model", "no_such_model"]]
    verbs += [["identify", verb, "no_such_model", "-m", str(loads)]
              for verb in ("direct", "iterative", "fit", "geometry")]
    verbs += [["identify", "correct", "no_such_model", "-m", str(loads), "--case", "a"]]
    first_builtin = next(iter(builtin_models()))
    for args in verbs:
        result = runner.invoke(app, args)
        text = " ".join(result.output.split())
        assert result.exit_code == 2, (args, result.output)
        assert "model 'no_such_model' is neither a built-in model" in text, (args, text)
        assert first_builtin in text and "Traceback" not in text, (args, text)
    # a missing model file: the same loader, the file named
    result = runner.invoke(app, ["info", str(tmp_path / "missing.toml")])
    assert result.exit_code == 2 and "no such file" in " ".join(result.output.split())
    assert "missing.toml" in result.output
