"""The decode path (scanner/, viewer/ and what they import) never imports torch or kornia (DESIGN section 2)."""
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _modules(folder: str, package: str) -> list[str]:
    return sorted(package + ("." + p.stem if p.stem != "__init__" else "") for p in (ROOT / folder).glob("*.py")
                  if p.stem != "__main__")


# every module of the core, the scanner and the viewer: the phone side and what it stands on
DECODE_PATH = _modules("snapshot3d", "snapshot3d") + _modules("scanner", "snapshot3d.scanner") + \
    _modules("viewer", "snapshot3d.viewer")

BLOCKER = """
import sys
class _Block:
    def find_spec(self, name, path=None, target=None):
        if name.split('.')[0] in ('torch', 'kornia'):
            raise ImportError(f'{name} is blocked: the decode path must not import it')
sys.meta_path.insert(0, _Block())
"""


def test_decode_path_imports_without_torch():
    code = BLOCKER + "\n".join(f"import {m}" for m in DECODE_PATH) + """
import snapshot3d.cli
snapshot3d.cli.build_parser()
assert not any(m.split('.')[0] in ('torch', 'kornia') for m in sys.modules), 'torch leaked in'
print('ok')
"""
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert proc.returncode == 0 and proc.stdout.strip() == "ok", proc.stderr


def test_blocker_really_blocks():
    proc = subprocess.run([sys.executable, "-c", BLOCKER + "import snapshot3d.train.field.field"], capture_output=True, text=True)
    assert proc.returncode != 0 and "blocked" in proc.stderr
