"""`snapshot3d export -o DIR`: both ONNX models, checked against torch on real inputs."""
from __future__ import annotations

import json
from pathlib import Path

from snapshot3d.errors import UserError
from snapshot3d.paths import asset

__all__ = ["export_command"]


def export_command(args) -> int:
    from .onnx_export import export_all
    from .parity import restore_parity, shade_parity

    out = Path(args.output) if args.output else asset()
    if out.exists() and not out.is_dir():
        raise UserError(f"{out} is a file; export writes a folder of .onnx models")
    models = export_all(out)
    parity = {"shade": shade_parity(models["shade"]["path"]),
              "restore": restore_parity(models["restore"]["path"], models["shade"]["path"])}
    report = {"models": models, "parity": parity}
    (out / "export.json").write_text(json.dumps(report, indent=2) + "\n")
    bad = parity["shade"]["views_max_abs_diff"] > 1e-3 or parity["restore"]["restore_psnr_diff_db"] > 0.05
    print(json.dumps(parity))
    if bad:
        raise UserError("ONNX parity check failed: the exported models do not match torch (see export.json)")
    return 0
