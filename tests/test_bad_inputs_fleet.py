"""Bad inputs of `diffsusp fleet`: a
FIFO item fails alone (no hang), unknown options and a bad model are exit 2 before any item,
a damaged state file is named, summary cells are neutralised. No item is fitted here."""

import os

from typer.testing import CliRunner

from diffsusp.cli import app
from diffsusp.tyre import examples

TIR = examples.DATA / "PacejkaBook_Defaults.tir"


def _run(*args):
    return CliRunner().invoke(app, ["fleet", *map(str, args)])


def _text(r):
    return " ".join(r.output.split())


def test_fleet_bad_inputs(tmp_path):
    out = tmp_path / "out"
    fifo = tmp_path / "=HYPERLINK(1).csv"
    os.mkfifo(fifo)
    r = _run("tyre-fit", "--items", fifo, "--out", out, "--model", TIR)
    assert r.exit_code == 3 and "FIFO" in _text(r), r.output      # the item failed, alone
    summary = (out / "summary.csv").read_text()
    assert "'=HYPERLINK(1)" in summary and "\n=HYPERLINK" not in summary
    for opt in ("colour=red", 'groups=["lateral"]', "loss=square"):
        r = _run("tyre-fit", "--items", fifo, "--out", tmp_path / "o2", "--model", TIR,
                 "--option", opt)
        assert r.exit_code == 2 and opt.split("=")[0] in _text(r), (opt, r.output)
    for recipe, opt in (("direct", "colour=red"), ("iterative", "tolerance=1"),
                        ("least-squares", "sigmas=0.1"), ("kc", "event=bounce")):
        r = _run(recipe, "--items", fifo, "--out", tmp_path / "o4", "--model",
                 "pseudo_mcpherson", "--option", opt)
        assert r.exit_code == 2 and opt.split("=")[-1 if recipe == "kc" else 0] in _text(r), \
            (recipe, r.output)
    bad_model = tmp_path / "start.tir"
    bad_model.write_text("[MODEL]\nFITTYP = 61\n[VERTICAL]\nFNOMIN = -1\n")
    r = _run("tyre-fit", "--items", fifo, "--out", tmp_path / "o3", "--model", bad_model)
    assert r.exit_code == 2 and "FNOMIN" in _text(r), r.output
    (out / "fleet.json").write_text('{"items": [1, 2}\n')
    r = _run("status", out)
    assert r.exit_code == 2 and "fleet.json:1" in _text(r), r.output
    (out / "fleet.json").write_text('{"items": []}\n')
    (out / "journal.jsonl").write_text('{"item": "a", "hash": "x", "status": "ok"}\n[1, 2]\n')
    r = _run("status", out)
    assert r.exit_code == 2 and "journal.jsonl:2" in _text(r), r.output
