"""`snapshot3d export -o DIR` (or `--install`): the ONNX models, checked against torch (the print receiver
against its numpy reference) on real inputs.

The models are written and checked in a hidden staging folder first; only models that pass the parity
check replace what stands in the destination (the package's shipped models with `--install`)."""
from __future__ import annotations

import json
import os
import shutil
import tempfile
from pathlib import Path

from snapshot3d import formats
from snapshot3d.errors import UserError
from snapshot3d.paths import asset

__all__ = ["export_command"]


def export_command(args) -> int:
    from .onnx_export import decoder_keys, export_all, restore_keys
    from .parity import field_parity, print_graph_agrees, print_parity, restore_parity

    out = asset() if args.install else Path(args.output)
    if out.exists() and not out.is_dir():
        raise UserError(f"{out} is a file; export writes a folder of .onnx models")
    out.mkdir(parents=True, exist_ok=True)
    stage = Path(tempfile.mkdtemp(prefix=".export.", suffix=".partial", dir=out))
    try:
        models = export_all(stage)
        paths = {k: v["path"] for k, v in models.items()}
        parity = {("field" if d == formats.DECODER_VERSION else f"field-{d}"):
                  field_parity(paths[k], paths[k.replace("project", "field", 1)], decoder=d)
                  for k, (g, d) in decoder_keys().items() if g == "project"}
        parity.update({k: restore_parity(paths[k], codec=c) for k, c in restore_keys().items()})
        parity["restore-print"] = print_parity(paths["restore-print"])
        print(json.dumps(parity))
        if any(parity[k]["views_max_abs_diff"] > 1e-3 for k in parity if k.startswith("field")) or \
                any(parity[k]["restore_psnr_diff_db"] > 0.05 for k in restore_keys()) or \
                any(not print_graph_agrees(v) for v in parity["restore-print"].values()):
            raise UserError("ONNX parity check failed: the exported models do not match torch (or the print receiver's "
                            "numpy reference); nothing was written")
        for info in models.values():
            final = out / Path(info["path"]).name
            os.replace(info["path"], final)
            info["path"] = final.name  # relative to export.json's folder
        (out / "export.json").write_text(json.dumps({"models": models, "parity": parity}, indent=2) + "\n")
        if args.vectors:
            from .conformance import write_vectors
            write_vectors(args.vectors, {k: out / v["path"] for k, v in models.items()})
            print(f"wrote the conformance vectors of these models to {args.vectors}")
    finally:
        shutil.rmtree(stage, ignore_errors=True)
    print(f"wrote {', '.join(m['path'] for m in models.values())} and export.json to {out}/")
    return 0
