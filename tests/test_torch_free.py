"""The decode path (scanner/, viewer/ and what they import) never imports torch or kornia (DESIGN section 2)."""
import subprocess
import sys

DECODE_PATH = ["snapshot3d.scanner", "snapshot3d.viewer", "snapshot3d.cameras", "snapshot3d.scene",
               "snapshot3d.formats", "snapshot3d.loaders", "snapshot3d.builtin", "snapshot3d.meshing",
               "snapshot3d.images", "snapshot3d.metrics", "snapshot3d.cli",
               "snapshot3d.scanner.sheet", "snapshot3d.scanner.simulate", "snapshot3d.scanner.scan",
               "snapshot3d.scanner.commands", "snapshot3d.scanner.bench", "snapshot3d.scanner.cli",
               "snapshot3d.scanner.imageio_safe", "snapshot3d.scanner.colour", "snapshot3d.scanner.qr",
               "snapshot3d.codec_layout", "snapshot3d.scanner.snapfile", "snapshot3d.scanner.channel_fit",
               "snapshot3d.viewer.runtime", "snapshot3d.viewer.march", "snapshot3d.viewer.render",
               "snapshot3d.viewer.decode", "snapshot3d.viewer.commands", "snapshot3d.viewer.demo"]

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
    proc = subprocess.run([sys.executable, "-c", BLOCKER + "import snapshot3d.train.field"], capture_output=True, text=True)
    assert proc.returncode != 0 and "blocked" in proc.stderr
