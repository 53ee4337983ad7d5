"""A fleet's output folder: reports streamed to disk as they finish, a journal, a summary.

```
OUT/
  fleet.json          what ran: recipe, options, model fingerprint, the items and their hashes
  journal.jsonl       one line per finished item (appended, one fsync per batch): item, hash,
                      status, message, summary values, seconds, worker, batch
  reports/ITEM.json   the item's report, as the single-item verb writes it (--out x.json)
  summary.csv         one row per item: item, status, message, hash, then the estimates,
                      each with its identification status (`<name> status`)
```

Nothing finished is lost: a line is in the journal (and the report on disk) as soon as its
batch returns. A re-run skips every item whose journal line has the same content hash (the
item's bytes, the recipe and its options, the model); `retry_failed=True` re-runs the failed
ones. The summary is rebuilt from the journal (the last line of each item) at the end of a run
and by `status`; it holds no timing or worker, so the same fleet on any engine gives the same
summary.
"""

import csv
import dataclasses
import json
import math
import os
import pathlib

from ..errors import InputError, ModelFileError
from ..io.files import read_input, write_text_atomic

__all__ = ["FleetStatus", "Store", "status"]

SUMMARY_HEAD = ("item", "status", "message", "hash")


def _number(v):
    return None if v is None or (isinstance(v, float) and not math.isfinite(v)) else v


class Store:
    """The output folder of a fleet (see the module docstring)."""

    def __init__(self, out):
        self.out = pathlib.Path(out)
        self.reports = self.out / "reports"
        self.journal_path = self.out / "journal.jsonl"

    def open(self, manifest: dict) -> None:
        self.reports.mkdir(parents=True, exist_ok=True)
        write_text_atomic(self.out / "fleet.json", json.dumps(manifest, indent=1) + "\n")

    def entries(self) -> dict[str, dict]:
        """The last journal line of every item."""
        last: dict[str, dict] = {}
        if not self.journal_path.exists():
            return last
        # a regular file within the table limit (never a FIFO); a line that is not JSON (cut
        # by a crash) is skipped, that item re-runs; a JSON line that is not an entry is an
        # error naming the line
        data = read_input(self.journal_path, "fleet journal", "table")
        for k, raw in enumerate(data.splitlines(), start=1):
            line = raw.decode("utf-8", errors="replace").strip()
            if not line:
                continue
            try:
                entry = json.loads(line)
            except json.JSONDecodeError:  # a line cut by a crash: that item re-runs
                continue
            if not (isinstance(entry, dict) and isinstance(entry.get("item"), str)
                    and isinstance(entry.get("hash"), str)
                    and isinstance(entry.get("status"), str)):
                raise ModelFileError("not a journal entry (item, hash, status); the fleet's "
                                     "folder is damaged: remove journal.jsonl to run every "
                                     "item again", path=self.journal_path, line=k)
            last[entry["item"]] = entry
        return last

    def record(self, entry: dict, report: dict | None) -> None:
        """Write an item's report, then its journal line (flushed)."""
        self.record_batch([(entry, report)])

    def record_batch(self, done: list[tuple[dict, dict | None]]) -> None:
        """Write the reports of the items of a batch, then their journal lines in one write
        and one fsync (a fleet of 10⁵ items syncs once per batch, not once per item). A crash
        in between leaves reports without a line: those items run again."""
        for entry, report in done:
            if report is not None:
                write_text_atomic(self.reports / f"{entry['item']}.json",
                              json.dumps(report, indent=1, default=_jsonable) + "\n")
        with open(self.journal_path, "a", encoding="utf-8") as f:
            f.write("".join(json.dumps(entry, default=_jsonable) + "\n" for entry, _ in done))
            f.flush()
            os.fsync(f.fileno())

    def manifest(self) -> dict:
        """The folder's `fleet.json` ({} when there is none). A damaged one (not a regular
        file, not UTF-8 JSON, not a fleet's manifest) is an error naming the file and the line:
        remove it to start the fleet again."""
        path = self.out / "fleet.json"
        if not path.exists():
            return {}
        data = read_input(path, "fleet state")
        fix = "; the fleet's folder is damaged: remove fleet.json (and journal.jsonl) to " \
              "run every item again"
        try:
            doc = json.loads(data.decode("utf-8"))
        except UnicodeDecodeError:
            raise ModelFileError(f"not UTF-8 text{fix}", path=path) from None
        except json.JSONDecodeError as e:
            raise ModelFileError(f"not valid JSON ({e.msg}){fix}", path=path,
                                 line=e.lineno) from None
        items = doc.get("items", []) if isinstance(doc, dict) else None
        if not isinstance(items, list) or not all(
                isinstance(i, dict) and isinstance(i.get("item"), str)
                and isinstance(i.get("hash"), str) for i in items):
            raise ModelFileError(f"not a fleet's state (items with item and hash){fix}",
                                 path=path, field="items")
        return doc

    def write_summary(self) -> pathlib.Path:
        """summary.csv from the journal: one row per item of the manifest that has a line,
        in item order."""
        entries = self.entries()
        order = [i["item"] for i in self.manifest().get("items", [])] or sorted(entries)
        names: list[str] = []
        for item in order:
            for name in entries.get(item, {}).get("values") or {}:
                if name not in names:
                    names.append(name)
        path = self.out / "summary.csv"
        tmp = path.with_name(f".summary.{os.getpid()}.tmp")
        with open(tmp, "w", newline="", encoding="utf-8") as f:
            writer = csv.writer(f)
            writer.writerow([*SUMMARY_HEAD, *names])
            for item in order:
                if item not in entries:
                    continue
                e = entries[item]
                values = e.get("values") or {}
                writer.writerow([_cell(item), _cell(e["status"]), _cell(e.get("message") or ""),
                                 _cell(e["hash"]),
                                 *(_cell(values.get(n)) for n in names)])
        os.replace(tmp, path)
        return path


def _cell(v) -> str:
    """A summary cell: a number as Python writes it (round-trips); a text with its control
    characters escaped (a newline in an item's name cannot forge a row) and, when a spreadsheet
    would run it as a formula (leading = + - @, not a number), quoted with '."""
    if v is None:
        return ""
    if not isinstance(v, str):
        return repr(v)
    text = "".join(c if c.isprintable() else c.encode("unicode_escape").decode("ascii")
                   for c in v)
    if text[:1] in ("=", "+", "-", "@"):
        try:
            float(text)
        except ValueError:
            return "'" + text
    return text


def _jsonable(x):
    import numpy as np

    if isinstance(x, np.ndarray | np.generic):
        return x.tolist()
    if hasattr(x, "__array__"):
        return np.asarray(x).tolist()
    if isinstance(x, float):
        return _number(x)
    raise TypeError(f"not JSON serialisable: {type(x).__name__}")


@dataclasses.dataclass(frozen=True)
class FleetStatus:
    """What a fleet's folder holds: items in the manifest, finished ok, failed (with their
    messages), still to do, and the rate of the last run (items per second of wall time)."""

    out: pathlib.Path
    recipe: str
    total: int
    ok: int
    failed: int
    pending: int
    failures: tuple[tuple[str, str, str], ...]  # (item, status, message)
    items_per_s: float

    def text(self) -> str:
        lines = [f"{self.out}: recipe {self.recipe}, {self.total} items: {self.ok} ok, "
                 f"{self.failed} failed, {self.pending} to do"
                 + (f"; last run {self.items_per_s:.3g} items/s" if self.items_per_s else "")]
        lines += [f"  {item}: {st}: {msg}" for item, st, msg in self.failures]
        return "\n".join(lines)


def status(out) -> FleetStatus:
    """The state of the fleet in folder `out` (also `diffsusp fleet status OUT`)."""
    store = Store(out)
    manifest = store.manifest()
    if not manifest:
        raise InputError(f"{out} holds no fleet (no fleet.json): run one there first.")
    entries = store.entries()
    hashes = {i["item"]: i["hash"] for i in manifest.get("items", [])}
    current = {k: e for k, e in entries.items() if hashes.get(k) == e["hash"]}
    ok = sum(e["status"] == "ok" for e in current.values())
    failures = tuple((k, e["status"], e.get("message") or "") for k, e in sorted(current.items())
                     if e["status"] != "ok")
    run = manifest.get("last_run") or {}
    return FleetStatus(out=pathlib.Path(out), recipe=manifest.get("recipe", "?"),
                       total=len(hashes), ok=ok, failed=len(failures),
                       pending=len(hashes) - len(current), failures=failures,
                       items_per_s=float(run.get("items_per_s") or 0.0))


