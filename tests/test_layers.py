"""The one-way layering of the packages (README "Layout"): the core `snapshot3d/` at the bottom, the
torch-free `scanner/` and `viewer/` above it, `train/` above those, `export/` above `train/`, `bench/` on
top. Product code never imports `snapshot3d.bench` (measurement is not product)."""
import ast
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LAYERS = {"": 0, "scanner": 1, "viewer": 2, "train": 3, "export": 4, "bench": 5}
FOLDERS = {"snapshot3d": "", "scanner": "scanner", "viewer": "viewer", "train": "train", "export": "export",
           "bench": "bench"}
# The command line is the entry point: it names every layer's commands (lazily, by module path strings).
ENTRY = {"snapshot3d.cli", "snapshot3d.cli_bench", "snapshot3d.__main__"}


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
            if module in ENTRY:
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
