"""The decode's quality estimate without ground truth: the `restore_psnr` a decode can expect, from what
the capture itself says. Each codec ships a calibration written by `snapshot3d bench decode`:
- print medium: the codec's own pilots measure the gain and the noise of this capture, hence the planes'
  expected error (`print_read.Reading.plane_rmse`); what that error does to this scene's own views
  (`viewer.quality_views`, `views_psnr_expected`) is the predictor, and a line in it gives the restore_psnr
  (a calibration whose predictor is "log10(plane_rmse_expected)", as shipped before, still reads);
- file medium: the sheet's ArUco markers are a pilot signal that went through the same channel
  (`scanner.pilot.pilot_psnr`); a line in it gives the restore_psnr.
numpy only."""
from __future__ import annotations

import json
import math
from functools import lru_cache

from snapshot3d.codecs.media import CODEC_MEDIUM
from snapshot3d.paths import asset

__all__ = ["calibration_file", "load_calibration", "quality_estimate", "predictor_value", "VIEWS_PREDICTOR"]


def calibration_file(codec: str) -> str:
    return f"quality-{codec}.json"


@lru_cache(maxsize=4)
def load_calibration(codec: str) -> dict | None:
    """{"predictor", "slope", "intercept", "range", held-out errors, "source"} or None when not shipped."""
    path = asset(calibration_file(codec))
    return json.loads(path.read_text()) if path.is_file() else None


VIEWS_PREDICTOR = "views_psnr_expected (dB)"
"""the print calibration's predictor since issue 38: `quality_views.views_psnr_expected`"""


def predictor_value(codec: str, pilot_psnr: float | None, plane_rmse: float | None,
                    views_psnr: float | None = None, predictor: str | None = None) -> float | None:
    """The number a codec's calibration line reads. Print: the views' expected PSNR (`predictor` None or
    VIEWS_PREDICTOR) or, for a calibration made before it, log10 of the expected plane RMS error. File: the
    markers' pilot_psnr in dB (None for a snapshot file, which has no markers)."""
    if CODEC_MEDIUM.get(codec) == "print":
        if predictor is None or predictor == VIEWS_PREDICTOR:
            return None if views_psnr is None else float(views_psnr)
        return math.log10(max(plane_rmse, 1e-6)) if plane_rmse is not None else None
    return None if pilot_psnr is None else float(pilot_psnr)


def quality_estimate(codec: str, pilot_psnr: float | None, plane_rmse: float | None = None,
                     views_psnr: float | None = None) -> dict:
    """The expected restore_psnr of a decode; `pilot_psnr` is the markers' (None for a snapshot file),
    `plane_rmse` and `views_psnr` the print codec's (`quality_views.views_psnr_expected`)."""
    cal = load_calibration(codec)
    x = predictor_value(codec, pilot_psnr, plane_rmse, views_psnr, cal["predictor"] if cal else None)
    print_codec = CODEC_MEDIUM.get(codec) == "print"
    out = {"pilot_psnr_db": None if pilot_psnr is None else round(float(pilot_psnr), 2),
           "plane_rmse_expected": plane_rmse,
           "views_psnr_expected_db": None if views_psnr is None else round(float(views_psnr), 2),
           "basis": "the codec's pilot carriers and this scene's views" if print_codec else
                    "the sheet's markers" if pilot_psnr is not None else "none: a snapshot file has no markers",
           "restore_psnr_expected_db": None, "calibration": None}
    if cal is not None and x is not None:
        lo, hi = cal.get("range") or cal["pilot_range"]
        x = min(max(x, lo), hi)  # no extrapolation past what was measured
        out["restore_psnr_expected_db"] = round(cal["intercept"] + cal["slope"] * x, 2)
        out["calibration"] = {k: cal.get(k) for k in ("predictor", "held_out_corr", "held_out_rmse_db", "source")}
    return out
