"""`io.read_iges` on hostile files: an entity of
200 000 parameters reads in linear time, a model scale that sends coordinates to infinity is
an error naming the line. The files are written here (a point and a line)."""

import time

import pytest

from diffsusp.errors import ModelFileError
from diffsusp.io.iges import read_iges


def _iges(scale="1.0", extra_params=0):
    """A small IGES file: a point (116) with `extra_params` trailing parameters and a line
    (110); global scale `scale`, millimetres."""
    def records(letter, chunks, width=72):
        return [f"{c:<{width}}{letter}{k + 1:7d}" for k, c in enumerate(chunks)]

    g = f"1H,,1H;,4Htest,,,,,,,,,,{scale},2,2HMM;"
    glines = records("G", [g[i:i + 72] for i in range(0, len(g), 72)])
    point = "116,1.0,2.0,3.0" + ",0" * extra_params + ";"
    line = "110,0.0,0.0,0.0,10.0,0.0,0.0;"
    pchunks, owners = [], []
    for de, text in ((1, point), (3, line)):
        parts = [text[i:i + 64] for i in range(0, len(text), 64)]
        pchunks.append((len(owners) + 1, len(parts)))
        owners += [(p, de) for p in parts]
    plines = [f"{p:<64}{de:8d}P{k + 1:7d}" for k, (p, de) in enumerate(owners)]

    def fields(*v):
        return "".join(f"{x:>8}" for x in v)

    d = []
    for kind, (start, count), label in ((116, pchunks[0], "PT1"), (110, pchunks[1], "AX1")):
        d.append(fields(kind, start, 0, 0, 0, 0, 0, 0, "00000000"))
        d.append(fields(kind, 0, 0, count, 0, "", "", label, 0))
    dlines = records("D", d)
    s = records("S", ["bad_inputs D19"])
    t = records("T", [f"S{1:7d}G{len(glines):7d}D{len(dlines):7d}P{len(plines):7d}"])
    return "\n".join(s + glines + dlines + plines + t) + "\n"


def test_iges_long_entity_and_scale(tmp_path):
    f = read_iges(_iges())
    assert f.point("PT1").tolist() == [1.0, 2.0, 3.0] and f.lines[0].length == 10.0
    big = tmp_path / "long.igs"
    big.write_text(_iges(extra_params=200_000))   # 0.8 M characters in one entity
    t0 = time.perf_counter()
    f = read_iges(big)
    assert time.perf_counter() - t0 < 10.0          # with slices of the rest: ~26 s
    assert f.point("PT1").tolist() == [1.0, 2.0, 3.0]
    scaled = tmp_path / "scale.igs"
    scaled.write_text(_iges(scale="1.0D300"))
    with pytest.raises(ModelFileError, match=r"scale.igs:\d+: .*model scale 1e\+300"):
        read_iges(scaled)
