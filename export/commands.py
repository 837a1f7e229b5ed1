"""`snapshot3d export -o DIR`: the ONNX models, checked against torch on real inputs."""
from __future__ import annotations

import json
from pathlib import Path

from snapshot3d.errors import UserError
from snapshot3d.paths import asset

__all__ = ["export_command"]


def export_command(args) -> int:
    from .onnx_export import export_all
    from .parity import field_parity, restore_parity

    out = Path(args.output) if args.output else asset()
    if out.exists() and not out.is_dir():
        raise UserError(f"{out} is a file; export writes a folder of .onnx models")
    models = export_all(out)
    paths = {k: v["path"] for k, v in models.items()}
    parity = {"field": field_parity(paths["project"], paths["field"]),
              "restore": restore_parity(paths["restore"], paths["project"], paths["field"])}
    report = {"models": models, "parity": parity}
    (out / "export.json").write_text(json.dumps(report, indent=2) + "\n")
    bad = parity["field"]["views_max_abs_diff"] > 1e-3 or parity["restore"]["restore_psnr_diff_db"] > 0.05
    print(json.dumps(parity))
    if bad:
        raise UserError("ONNX parity check failed: the exported models do not match torch (see export.json)")
    return 0
