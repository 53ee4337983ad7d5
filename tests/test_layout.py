"""The package's layout, read from its own imports (AST, no import, no compilation):

- no `_private` name is imported from another module (a name a sibling needs is not private),
  and a private module (`identify/_direct.py`) is imported only by its own package: the others
  import the package's face (`from ..identify import direct`);
- no package binds a name of one of its public submodules to something else (a function that
  shadows its module: the module is private instead);
- internal imports inside functions only under `diffsusp/cli/` (lazy start-up of the command),
  except the edges listed in `LAZY` below (none today), each with its reason;
- no module-level `__getattr__` (no compatibility shims);
- no import circle (strongly connected modules, in-function imports counted) other than those
  in `CIRCLES` (none today).

ARCHITECTURE.md describes the layers. A new exception fails here until it is listed with its
reason, and a listed one that disappears fails too, so that the lists only shrink.
"""

import ast
import pathlib

ROOT = pathlib.Path(__file__).resolve().parent.parent / "diffsusp"

LAZY = set()
CIRCLES = set()


def _modules():
    mods = {}
    for path in sorted(ROOT.rglob("*.py")):
        parts = list(path.relative_to(ROOT.parent).with_suffix("").parts)
        mods[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return mods


def _target(name, path, node):
    """The absolute module an `ImportFrom` names (relative imports resolved)."""
    if not node.level:
        return node.module or ""
    parts = name.split(".")
    package = parts if path.name == "__init__.py" else parts[:-1]
    base = package[: len(package) - node.level + 1]
    return ".".join(base + ([node.module] if node.module else []))


def _scan():
    mods = _modules()
    private, lazy, shims = [], set(), []
    edges = {m: set() for m in mods}
    for name, path in mods.items():
        tree = ast.parse(path.read_text(encoding="utf-8"))
        inside = {id(n) for f in ast.walk(tree)
                  if isinstance(f, (ast.FunctionDef, ast.AsyncFunctionDef))
                  for n in ast.walk(f) if n is not f}
        for node in ast.walk(tree):
            if isinstance(node, ast.FunctionDef) and node.name == "__getattr__" \
                    and id(node) not in inside and node in tree.body:
                shims.append(name)
            if isinstance(node, ast.ImportFrom):
                target = _target(name, path, node)
                if not target.startswith("diffsusp"):
                    continue
                home = name if path.name == "__init__.py" else name.rpartition(".")[0]
                for alias in node.names:
                    sub = f"{target}.{alias.name}"
                    dest = sub if sub in mods else target
                    if dest in mods and dest != name:
                        edges[name].add(dest)
                    parts = dest.split(".")
                    if any(p.startswith("_") for p in parts) and \
                            not (home + ".").startswith(".".join(parts[:-1]) + "."):
                        private.append(f"{path.relative_to(ROOT.parent)}:{node.lineno} "
                                       f"{dest} (a private module outside its package)")
                    if path.name == "__init__.py" and node.level == 1 and node.module and \
                            f"{name}.{alias.asname or alias.name}" in mods:
                        shims.append(f"{name}.{alias.asname or alias.name} (a name that "
                                     "shadows its module)")
                    if alias.name.startswith("_") and not alias.name.startswith("__"):
                        private.append(f"{path.relative_to(ROOT.parent)}:{node.lineno} "
                                       f"{target}.{alias.name}")
                    if id(node) in inside and ".cli" not in name:
                        lazy.add((name, dest))
            elif isinstance(node, ast.Import):
                for alias in node.names:
                    if alias.name.startswith("diffsusp") and alias.name in mods:
                        edges[name].add(alias.name)
                        if id(node) in inside and ".cli" not in name:
                            lazy.add((name, alias.name))
    return private, lazy, shims, edges


def _circles(edges):
    """Strongly connected groups of more than one module (Tarjan, iterative)."""
    index, low, on, stack, out, counter = {}, {}, set(), [], [], [0]
    for root in edges:
        if root in index:
            continue
        work = [(root, iter(sorted(edges[root])))]
        index[root] = low[root] = counter[0]
        counter[0] += 1
        stack.append(root)
        on.add(root)
        while work:
            v, it = work[-1]
            for w in it:
                if w not in index:
                    index[w] = low[w] = counter[0]
                    counter[0] += 1
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(edges[w]))))
                    break
                if w in on:
                    low[v] = min(low[v], index[w])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[v])
                if low[v] == index[v]:
                    group = set()
                    while True:
                        w = stack.pop()
                        on.discard(w)
                        group.add(w)
                        if w == v:
                            break
                    if len(group) > 1:
                        out.append(frozenset(group))
    return set(out)


def test_one_face_per_module_no_hidden_doors():
    private, lazy, shims, edges = _scan()
    assert not private, "private names imported from another module:\n" + "\n".join(private)
    assert not shims, f"module-level __getattr__ shims, or names shadowing modules: {shims}"
    assert lazy == LAZY, ("internal imports inside functions outside cli/ (new: "
                          f"{sorted(lazy - LAZY)}; gone, remove from LAZY: {sorted(LAZY - lazy)})")
    assert _circles(edges) == CIRCLES, _circles(edges)


def test_the_scan_sees_what_it_forbids(tmp_path, monkeypatch):
    """The scan itself: a private import, a private module imported from another package, a
    lazy import, a shim, a name shadowing its module and a circle, all found."""
    pkg = tmp_path / "diffsusp"
    (pkg / "a").mkdir(parents=True)
    (pkg / "b").mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "a" / "__init__.py").write_text("from ._z import z\nfrom .x import x\n\n"
                                           "def __getattr__(name):\n    raise AttributeError\n")
    (pkg / "a" / "_z.py").write_text("def z():\n    pass\n")
    (pkg / "b" / "__init__.py").write_text("from ..a._z import z\n")
    (pkg / "a" / "x.py").write_text("from .y import _hidden\nx = 1\n")
    (pkg / "a" / "y.py").write_text("_hidden = 1\n\ndef f():\n    from . import x\n")
    monkeypatch.setattr(__import__(__name__), "ROOT", pkg)
    private, lazy, shims, edges = _scan()
    assert sorted(private) == [
        "diffsusp/a/x.py:1 diffsusp.a.y._hidden",
        "diffsusp/b/__init__.py:1 diffsusp.a._z (a private module outside its package)"]
    assert lazy == {("diffsusp.a.y", "diffsusp.a.x")}
    assert sorted(shims) == ["diffsusp.a", "diffsusp.a.x (a name that shadows its module)"]
    assert _circles(edges) == {frozenset({"diffsusp.a.x", "diffsusp.a.y"})}
