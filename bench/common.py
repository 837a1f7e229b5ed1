"""What every benchmark shares: the report writer (CSV rows, JSON summary with the command and the core
count), the channel a snapshot goes through (`simulate` + `scan`), the judge that scores restored planes
by their orbit views, medians, and matplotlib set up for files (Agg).

Images: snapshots (380, 380, 3) uint8 RGB; views (N, H, W, 3) float32 RGB in [0, 1]."""
from __future__ import annotations

import csv
import json
import os
import sys
from pathlib import Path

import cv2
import numpy as np

from snapshot3d import formats
from snapshot3d.errors import UserError
from snapshot3d.metrics import psnr as _psnr

__all__ = ["SEVERITIES", "PHYSICAL", "write_report", "write_rows", "psnr", "median", "capture_seeds",
           "through_channel", "ViewJudge", "pyplot", "bench_progress", "update_budget_curve", "RowBlocks",
           "jpeg_copy", "run_metadata"]

SEVERITIES = formats.SEVERITIES
PHYSICAL = ("mild", "moderate", "severe")


def write_rows(path: Path, rows: list[dict], fields: list[str] | None = None) -> None:
    """CSV of `rows`; columns `fields` (default: the union of the rows' keys, in first-seen order)."""
    fields = fields or list(dict.fromkeys(k for r in rows for k in r))
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=fields, extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)


def run_metadata() -> dict:
    """What every results JSON records about the run that wrote it (its "meta" entry): the UTC date and
    time, the commit (`git rev-parse --short HEAD`, with "+dirty" when the tree has changes; "unknown"
    outside a git checkout), os.cpu_count(), the platform, the CPU's model (with torch's kernels when this run
    imported torch), and the versions of python, numpy, opencv,
    onnxruntime and torch (torch only when this run imported it; "not installed" when absent)."""
    import datetime
    import platform
    import subprocess
    from importlib import metadata

    def git(*args: str) -> str | None:
        try:
            proc = subprocess.run(["git", *args], capture_output=True, text=True, timeout=10,
                                  cwd=Path(__file__).resolve().parent)
        except (OSError, subprocess.SubprocessError):
            return None
        return proc.stdout.strip() if proc.returncode == 0 else None

    def version(dist: str) -> str:
        try:
            return metadata.version(dist)
        except metadata.PackageNotFoundError:
            return "not installed"

    commit = git("rev-parse", "--short", "HEAD")
    if commit and git("status", "--porcelain", "--untracked-files=no"):
        commit += "+dirty"
    versions = {"python": platform.python_version(), "numpy": np.__version__, "opencv": cv2.__version__,
                "onnxruntime": version("onnxruntime")}
    cpu = _cpu_model() or platform.processor() or "unknown"
    if "torch" in sys.modules:
        versions["torch"] = sys.modules["torch"].__version__
        cpu += f" ({sys.modules['torch'].backends.cpu.get_cpu_capability()})"   # the kernels torch's fits ran
    return {"date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
            "commit": commit or "unknown", "cores": os.cpu_count(), "machine": platform.platform(), "cpu": cpu,
            "versions": versions}


def _cpu_model() -> str | None:
    """The CPU's model name from /proc/cpuinfo (None elsewhere). Fits of the same commit and seed on two CPUs can
    differ by about a dB (their float kernels round differently and a fit amplifies it; docs/capture.md)."""
    try:
        lines = Path("/proc/cpuinfo").read_text().splitlines()
    except OSError:
        return None
    return next((line.split(":", 1)[1].strip() for line in lines if line.startswith("model name")), None)


def write_report(out: Path, stem: str, rows: list[dict], doc: dict) -> dict:
    """Write out/stem.csv (rows) and out/stem.json (`doc` after "command", "cores" and "meta", see
    `run_metadata`); returns the JSON document."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    write_rows(out / f"{stem}.csv", rows)
    doc = {"command": "snapshot3d " + " ".join(sys.argv[1:]), "cores": os.cpu_count(), "meta": run_metadata(), **doc}
    (out / f"{stem}.json").write_text(json.dumps(doc, indent=2) + "\n")
    return doc


class RowBlocks:
    """A long benchmark's rows, computed in named blocks and appended to `path` (JSON lines, the first line
    the run's `signature`) as each block ends, so that a run killed part-way resumes where it stopped: a
    rerun with the same signature reuses the finished blocks. `finish()` removes the file."""

    def __init__(self, path: Path, signature: dict):
        self.path, self.done = Path(path), {}
        head = json.dumps(signature, sort_keys=True, default=str)
        lines = self.path.read_text().splitlines() if self.path.is_file() else []
        if lines and lines[0] == head:
            for line in lines[1:]:
                try:
                    rec = json.loads(line)
                except ValueError:
                    break  # the line the kill cut
                self.done[rec["key"]] = rec["rows"]
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.path.write_text(head + "\n" + "".join(json.dumps({"key": k, "rows": r}, default=float) + "\n"
                                                   for k, r in self.done.items()))

    def rows(self, key: str, compute) -> list[dict]:
        """The block `key`'s rows: from an earlier run when it finished there, else `compute()` (saved)."""
        if key not in self.done:
            self.done[key] = json.loads(json.dumps(compute(), default=float))
            with open(self.path, "a") as f:
                f.write(json.dumps({"key": key, "rows": self.done[key]}) + "\n")
        return self.done[key]

    def finish(self) -> None:
        self.path.unlink(missing_ok=True)


def jpeg_copy(rgb: np.ndarray, quality: int, sampling: int = cv2.IMWRITE_JPEG_SAMPLING_FACTOR_420) -> np.ndarray:
    """(H, W, 3) uint8 RGB through an OpenCV JPEG file at `quality` and chroma `sampling` (default 4:2:0)."""
    ok, buf = cv2.imencode(".jpg", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR),
                           [cv2.IMWRITE_JPEG_QUALITY, quality, cv2.IMWRITE_JPEG_SAMPLING_FACTOR, sampling])
    return cv2.cvtColor(cv2.imdecode(buf, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)


def psnr(a, b) -> float:
    """PSNR capped at 100 dB (an exact copy), so that reports stay valid JSON."""
    return float(min(_psnr(a, b), 100.0))


def median(rows: list[dict], key: str) -> float | None:
    """Median of `key` over the rows that have a value for it (None when none has)."""
    vals = [r[key] for r in rows if r.get(key) not in (None, "")]
    return float(np.median(vals)) if vals else None


def capture_seeds(severity: str, seeds: int):
    """Seeds to capture a severity with: `seeds` photos for the physical ones, one for the digital ones
    (a JPEG file or a lossless copy does not depend on the seed)."""
    return range(seeds) if severity in PHYSICAL else [0]


def through_channel(snap: np.ndarray, meta, severity: str, seed: int, dots: int = 4) -> np.ndarray | None:
    """snapshot (380, 380, 3) uint8 RGB -> the rectified snapshot `scan` gives from a simulated photo of
    its sheet (drawn at `dots` dots per snapshot pixel), or None when the sheet is not found."""
    from snapshot3d.scanner.roundtrip import capture

    try:
        return capture(snap, meta, severity, seed, sheet_dots=dots)
    except UserError:
        return None


class ViewJudge:
    """Renders the orbit views of planes (torch reference renderer) and scores them against the original
    scene's: `restore_psnr` of restored planes."""

    def __init__(self, scene, size: int):
        from snapshot3d.cameras import orbit_cameras
        from snapshot3d.train.field.decoder import scene_decoder

        self.scene, self.size, self.decoder = scene, size, scene_decoder(scene)
        self.cams = orbit_cameras(scene.orbit, formats.ORBIT_VIEWS, size)
        self.ref = self.views(scene.planes())

    def views(self, planes: np.ndarray) -> np.ndarray:
        import torch

        from snapshot3d.train.field.render import render_views
        return render_views(torch.from_numpy(np.ascontiguousarray(planes, np.float32)), self.decoder, self.scene.box,
                            *self.cams, self.size, self.size)

    def planes_psnr(self, planes: np.ndarray) -> float:
        """restore_psnr of planes (3, C, R, R), carried as 8-bit codes."""
        from snapshot3d.scene import dequantize_planes, quantize_planes
        return psnr(self.views(dequantize_planes(quantize_planes(planes))), self.ref)

    def restore_psnr(self, secret: np.ndarray) -> float:
        """restore_psnr of the file codec's restored secret (24, G, G)."""
        from snapshot3d.codecs import file_layout
        return self.planes_psnr(file_layout.secret_to_planes(secret, self.scene.resolution, self.scene.channels))


def pyplot():
    """matplotlib.pyplot drawing to files (the Agg backend), imported on first use."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def bench_progress(total: int, desc: str):
    """A progress bar (`snapshot3d.progress`) for a benchmark's `total` units of work."""
    from snapshot3d.progress import progress
    return progress(total, desc, unit="run")


def update_budget_curve(medium: str, points: list, severity: str, source: str) -> Path:
    """Write a medium's curve of payload size against restore fidelity, [(plane values, restore_psnr)],
    into the package's `budget-curves.json`, which `fit --budget auto --medium` reads (the medium's other
    entries, such as the print channel's model, are kept)."""
    from snapshot3d.paths import asset
    from snapshot3d.train.field.budget import CURVES_FILE

    path = asset(CURVES_FILE)
    curves = json.loads(path.read_text()) if path.is_file() else {}
    curves[medium] = {**curves.get(medium, {}), "severity": severity, "source": source,
                      "points": sorted([int(v), round(float(p), 3)] for v, p in points)}
    path.write_text(json.dumps(curves, indent=2) + "\n")
    return path
