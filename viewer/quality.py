"""The decode's quality estimate without ground truth: the sheet's markers as a pilot signal
(`scanner.pilot.pilot_psnr`), mapped to the `restore_psnr` it predicts by a straight line fitted by
`snapshot3d bench decode` on simulated captures of every severity (the calibration ships with the
package, one per codec). numpy only."""
from __future__ import annotations

import json
from functools import lru_cache

from snapshot3d import formats
from snapshot3d.paths import asset

__all__ = ["CALIBRATION_FILE", "load_calibration", "quality_estimate"]

CALIBRATION_FILE = f"quality-{formats.CODEC_VERSION}.json"


@lru_cache(maxsize=1)
def load_calibration() -> dict | None:
    """{"slope", "intercept", "pilot_range", "fit": {...}} or None when the package has none."""
    path = asset(CALIBRATION_FILE)
    return json.loads(path.read_text()) if path.is_file() else None


def quality_estimate(pilot_psnr: float) -> dict:
    cal = load_calibration()
    out = {"pilot_psnr_db": round(float(pilot_psnr), 2), "restore_psnr_expected_db": None, "calibration": None}
    if cal is not None:
        lo, hi = cal["pilot_range"]
        p = min(max(float(pilot_psnr), lo), hi)  # no extrapolation past what was measured
        out["restore_psnr_expected_db"] = round(cal["intercept"] + cal["slope"] * p, 2)
        out["calibration"] = {k: cal[k] for k in ("held_out_corr", "held_out_rmse_db", "source")}
    return out
