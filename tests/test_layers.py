"""The one-way layering of the packages (README "Layout"): the core `snapshot3d/` at the bottom, the
torch-free `scanner/` and `viewer/` above it, `train/` above those, `export/` above `train/`, `bench/` on
top. Product code never imports `snapshot3d.bench` (measurement is not product). No module imports itself,
directly or around a circle of modules."""
import ast
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LAYERS = {"": 0, "scanner": 1, "viewer": 2, "train": 3, "export": 4, "bench": 5}
FOLDERS = {"snapshot3d": "", "scanner": "scanner", "viewer": "viewer", "train": "train", "export": "export",
           "bench": "bench"}
# The command line is the entry point: it names every layer's commands (lazily, by module path strings), and
# its parsers read the torch-free config dataclasses of the layers above.
ENTRY_PACKAGE = "snapshot3d.cli"
ENTRY = {"snapshot3d.__main__"}


def _is_entry(module: str) -> bool:
    return module in ENTRY or module == ENTRY_PACKAGE or module.startswith(ENTRY_PACKAGE + ".")


def _module(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    parts = parts[1:] if parts[0] == "snapshot3d" else parts
    parts = parts[:-1] if parts[-1] == "__init__" else parts
    return ".".join(["snapshot3d", *parts])


def _layer(module: str):
    parts = module.split(".")
    if parts[0] != "snapshot3d":
        return None
    return LAYERS.get(parts[1], 0) if len(parts) > 1 else 0


def _imports(path: Path, module: str):
    package = module if path.name == "__init__.py" else module.rsplit(".", 1)[0]
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            yield node.lineno, [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[:len(package.split(".")) - node.level + 1]
                yield node.lineno, [".".join(base + ([node.module] if node.module else []))]
            else:
                yield node.lineno, [node.module]


def product_modules() -> list[str]:
    return sorted(_module(p) for folder in FOLDERS if folder != "bench" for p in (ROOT / folder).rglob("*.py"))


def test_imports_point_down_only():
    """Every import, module-level or inside a function, targets the module's own layer or a lower one."""
    bad = []
    for folder in FOLDERS:
        for path in (ROOT / folder).rglob("*.py"):
            module = _module(path)
            if _is_entry(module):
                continue
            for line, targets in _imports(path, module):
                for t in targets:
                    if (_layer(t or "") or 0) > _layer(module):
                        bad.append(f"{path.relative_to(ROOT)}:{line} imports {t}")
    assert not bad, "\n".join(bad)


def test_checker_sees_an_upward_import(tmp_path):
    """The rule above can fail: a scanner module importing train is caught."""
    fake = ROOT / "scanner" / "_layers_probe.py"
    fake.write_text("def f():\n    from snapshot3d.train.field import fit\n")
    try:
        found = [t for _, ts in _imports(fake, _module(fake)) for t in ts if (_layer(t) or 0) > _layer(_module(fake))]
    finally:
        fake.unlink()
    assert found == ["snapshot3d.train.field"]


BENCH_BLOCKER = """
import sys
class _Block:
    def find_spec(self, name, path=None, target=None):
        if name == 'snapshot3d.bench' or name.startswith('snapshot3d.bench.'):
            raise ImportError(f'{name} is blocked: product code must not import the benchmarks')
sys.meta_path.insert(0, _Block())
"""


def test_product_runs_without_the_benchmarks():
    """Every product module imports, and the CLI builds its parser, with snapshot3d.bench unimportable."""
    mods = [m for m in product_modules() if m not in ("snapshot3d.__main__",)]
    code = BENCH_BLOCKER + "\n".join(f"import {m}" for m in mods) + """
import snapshot3d.cli
snapshot3d.cli.build_parser()
assert not any(m.startswith('snapshot3d.bench') for m in sys.modules), 'bench leaked in'
print('ok', len(sys.modules))
"""
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
    assert proc.returncode == 0 and proc.stdout.startswith("ok"), proc.stderr[-2000:]
    blocked = subprocess.run([sys.executable, "-c", BENCH_BLOCKER + "import snapshot3d.bench.common"],
                             capture_output=True, text=True)
    assert blocked.returncode != 0 and "blocked" in blocked.stderr


def all_modules() -> dict[str, Path]:
    """Every module of the project (its packages included) -> its file."""
    return {_module(p): p for folder in FOLDERS for p in (ROOT / folder).rglob("*.py")}


def import_graph(modules: dict[str, Path]) -> dict[str, set[str]]:
    """module -> the project modules it imports, at module level or inside a function. `from P import N`
    counts as an import of the module P.N when there is one, else of P; relative imports are resolved."""
    graph = {}
    for module, path in modules.items():
        package = module if path.name == "__init__.py" else module.rsplit(".", 1)[0]
        edges = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                edges.update(a.name for a in node.names)
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = package.split(".")[:len(package.split(".")) - node.level + 1]
                    source = ".".join(base + ([node.module] if node.module else []))
                else:
                    source = node.module
                edges.update(f"{source}.{a.name}" if f"{source}.{a.name}" in modules else source for a in node.names)
        graph[module] = edges & set(modules)
    return graph


def import_circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of the import graph with more than one module, and every module that
    imports itself (Tarjan's algorithm, iterative)."""
    index, low, on_stack, stack, circles = {}, {}, set(), [], []
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph[child]))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                comp = []
                while True:
                    m = stack.pop()
                    on_stack.discard(m)
                    comp.append(m)
                    if m == node:
                        break
                if len(comp) > 1 or node in graph[node]:
                    circles.append(sorted(comp))
    return circles


def test_no_import_circles():
    """No module reaches itself through the imports of the project's modules (module-level or in functions)."""
    circles = import_circles(import_graph(all_modules()))
    assert not circles, "import circles:\n" + "\n".join(" <-> ".join(c) for c in circles)


def test_checker_sees_an_import_circle():
    """The rule above can fail: a planted circle of two modules, and a module importing itself, are caught,
    through relative and function-level imports alike."""
    modules = all_modules()
    probes = {"snapshot3d.scanner._circle_probe_a": ROOT / "scanner" / "_circle_probe_a.py",
              "snapshot3d.scanner._circle_probe_b": ROOT / "scanner" / "_circle_probe_b.py",
              "snapshot3d.scanner._circle_probe_c": ROOT / "scanner" / "_circle_probe_c.py"}
    texts = ["from . import _circle_probe_b\n",
             "def f():\n    from snapshot3d.scanner._circle_probe_a import f\n",
             "def g():\n    from . import _circle_probe_c\n"]
    for path, text in zip(probes.values(), texts):
        path.write_text(text)
    try:
        assert {m: _module(p) for m, p in probes.items()} == {m: m for m in probes}
        circles = import_circles(import_graph({**modules, **probes}))
    finally:
        for path in probes.values():
            path.unlink()
    planted = sorted(c for c in circles if set(c) & set(probes))
    assert planted == [["snapshot3d.scanner._circle_probe_a", "snapshot3d.scanner._circle_probe_b"],
                       ["snapshot3d.scanner._circle_probe_c"]]

