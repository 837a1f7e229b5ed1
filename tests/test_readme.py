"""The README's by-hand pipeline runs as written, in order, from an empty folder (with small settings
appended so that it takes seconds: fewer fit steps and refinement steps, fewer and smaller views)."""
import re
import shlex
from pathlib import Path

import pytest
from helpers import run_cli

from snapshot3d.builtin import shared_data_dir

README = Path(__file__).resolve().parents[1] / "README.md"
# appended to each command of the README's pipeline: speed only, nothing that changes what runs
SMALL = {"fit": ["--steps", "12", "--size", "48", "--occ-warmup", "4", "--batch-rays", "1024"], "embed": ["--refine", "2"],
         "decode": ["--views", "3", "--size", "64"]}


def pipeline() -> list[list[str]]:
    """The commands of the README's fenced block that follows "The whole pipeline by hand"."""
    text = README.read_text()
    block = re.search(r"The whole pipeline by hand.*?```bash\n(.*?)```", text, re.S).group(1)
    return [shlex.split(line.split("#")[0]) for line in block.splitlines() if line.strip()]


def test_readme_pipeline_runs_in_order(tmp_path):
    if shared_data_dir() is None:   # the pipeline fits builtin:spot, whose mesh is shared data, not shipped
        pytest.skip("../shared/data is absent: the README's pipeline fits builtin:spot from its shared mesh")
    cmds = pipeline()
    assert [c[1] for c in cmds] == ["fit", "embed", "sheet", "simulate", "decode"]
    for cmd in cmds:
        assert cmd[0] == "snapshot3d"
        args = [a if not a.endswith("/") else a.rstrip("/") for a in cmd[1:]]
        proc = run_cli(*args, *SMALL.get(args[0], []), cwd=tmp_path, timeout=300)
        assert proc.returncode == 0, f"{' '.join(cmd)}\n{proc.stderr[-1500:]}"
    out = tmp_path / "out"
    assert sorted(p.name for p in (out / "views").iterdir()) == ["000.png", "001.png", "002.png"]
    assert {"turntable.gif", "contact.png", "report.json", "scene.s3d", "mesh.glb"} <= {p.name for p in out.iterdir()}
    assert (tmp_path / "sheet.pdf").read_bytes().startswith(b"%PDF") and (tmp_path / "sheet.png").is_file()
