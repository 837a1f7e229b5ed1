"""A channel profile (`snapshot3d calibrate`'s JSON) as parameters the rest of the project runs on (issue 38
item 3); numpy only (the phone side).

- `profile_preset`: a `simulate` preset that photographs like the profile. It starts from the profile's
  nearest preset, fixes the pose's scale and keeps its tilt small (the profile's MTF50 is in snapshot pixels,
  the simulator's blur in photo pixels), and sets one defocus radius and one scale of the sensor noise:
  the pair that brings the chart's MTF50, band gain and noise per coefficient nearest the profile's (in
  units of each measure's spread between photos, `_SPREAD`), read off `TABLE`: the chart measured through
  each preset on a grid of radius x noise scale (`reference_table`, 3 seeds a cell), bilinear in radius
  and log noise scale, in log measures. (The noise per coefficient follows the blur first: the halftone's
  texture dominates it until the sensor's noise is about 10 times the preset's.)
- `profile_channel`: the print channel's model (`print_channel.ChannelModel`) that the budget predicts with:
  the budget's `moderate` model (measured by the pilots in real hosts, `budget-curves.json`) times the
  profile's `print_channel` relative to the chart's own reading of `moderate` photos (`MODERATE_READING`).
  The chart reads the channel on mid grey, without a host's interference, so its values are taken relative
  to a preset, not as they are; `severity_position` says where the profile lies between the presets.

TABLE holds for the chart `calib-2` and the chart measure of 2026-11-26 07:10 UTC (MTF in the photo's linear
light, channel unit robust to the halftone's moire), MODERATE_READING for the `print_channel` measure of
04:30 UTC (unchanged since); a change to either needs them measured again (`reference_table`,
`reading_reference`)."""
from __future__ import annotations

import json
from dataclasses import replace

import numpy as np

from .calibrate import PRESET_REFERENCE
from .presets import Preset, get_preset

__all__ = ["TABLE", "MODERATE_READING", "COVERAGE", "TILT_DEG", "profile_preset", "profile_channel",
           "severity_position", "reference_table", "reading_reference", "base_preset"]

COVERAGE = 0.13
"""snapshot area / frame area of a profile's photos (the presets' median placement is 0.15; 7 in 10 photos
place the sheet at 0.13 at once, the rest shrink it, 0.11 in the median of those: `pose.sample_pose`)"""
TILT_DEG = (0.0, 15.0)
"""tilt of a profile's photos: small, so that a radius in photo pixels is one blur in snapshot pixels"""
_SPREAD = {"mtf50": 0.07, "gain": 0.135, "unit": 0.25}
"""log std of each measure over photos of one fixed condition (`base_preset("moderate", 2, 1)`, 6 seeds): the
solve weighs each target by it. The halftone's moire made most of it (without halftone: 0.16, 0.06, 0.14);
the unit's is 0.25 since it is read robustly (`chart_measure._median_power`; 0.50 before, both on
`base_preset("moderate", 1.5, 1)`, seeds 40-45); mtf50 and gain were measured with the measure before"""
_KEYS = ("mtf50", "gain", "unit")
MODERATE_READING = (0.435, 4.65)
"""the chart's median `print_channel` (gain, unit) over 12 `moderate` photos, seeds 100-111 (`reading_reference()`,
2026-11-26; log std over the photos 0.19 and 0.20)"""
TABLE = {
    # the chart (calib-2) measured through `base_preset(name, defocus, noise)`: medians over seeds 200-202 of mtf50,
    # channel gain and channel unit, rows by defocus (photo pixels), columns by noise scale (`reference_table()`,
    # 2026-11-26 07:10 UTC: MTF in the photo's linear light, unit robust to moire; the same photos as before)
    "mild": {"defocus": [0.0, 0.75, 1.5, 2.5, 4.0], "noise": [1.0, 4.0, 16.0, 64.0],
        "mtf50": [[0.4994, 0.5084, 0.5128, 0.5035],
                  [0.4396, 0.4317, 0.4324, 0.4149],
                  [0.3688, 0.3688, 0.3638, 0.349],
                  [0.2895, 0.2898, 0.2908, 0.2837],
                  [0.2265, 0.2256, 0.2264, 0.2254]],
        "gain": [[0.845, 0.8415, 0.8247, 0.8348],
                 [0.7965, 0.7927, 0.7789, 0.7604],
                 [0.6918, 0.6918, 0.6809, 0.673],
                 [0.518, 0.5188, 0.5156, 0.5083],
                 [0.3062, 0.3055, 0.3067, 0.3037]],
        "unit": [[0.001767, 0.001833, 0.00208, 0.00368],
                 [0.001272, 0.001279, 0.001369, 0.0027],
                 [0.001101, 0.001134, 0.001236, 0.002339],
                 [0.001226, 0.001251, 0.001358, 0.002616],
                 [0.001364, 0.001391, 0.001548, 0.003039]]},
    "moderate": {"defocus": [0.0, 0.75, 1.5, 2.5, 4.0], "noise": [1.0, 4.0, 16.0, 64.0],
        "mtf50": [[0.5179, 0.5343, 0.4871, 0.3186],
                  [0.4367, 0.4296, 0.3207, 0.2979],
                  [0.3573, 0.3526, 0.311, 0.2782],
                  [0.2884, 0.2868, 0.2767, 0.2375],
                  [0.2261, 0.2254, 0.2194, 0.2039]],
        "gain": [[0.727, 0.7271, 0.7421, 0.7693],
                 [0.6336, 0.6292, 0.5931, 0.6273],
                 [0.5532, 0.5504, 0.4987, 0.5626],
                 [0.3994, 0.3999, 0.4061, 0.4507],
                 [0.2521, 0.2518, 0.2537, 0.271]],
        "unit": [[0.002001, 0.002168, 0.003749, 0.01619],
                 [0.001248, 0.001336, 0.003114, 0.01585],
                 [0.001079, 0.001172, 0.00256, 0.01607],
                 [0.001449, 0.00153, 0.002496, 0.01544],
                 [0.001135, 0.001253, 0.002339, 0.01517]]},
    "severe": {"defocus": [0.0, 0.75, 1.5, 2.5, 4.0], "noise": [1.0, 4.0, 16.0, 64.0],
        "mtf50": [[0.4721, 0.438, 0.2849, 0.2511],
                  [0.3986, 0.399, 0.2589, 0.2607],
                  [0.356, 0.343, 0.2346, 0.2234],
                  [0.2916, 0.2827, 0.2132, 0.1944],
                  [0.2325, 0.2275, 0.1876, 0.1746]],
        "gain": [[0.7401, 0.7544, 0.8437, 0.533],
                 [0.63, 0.6341, 0.6907, 0.5367],
                 [0.5668, 0.5553, 0.61, 0.4715],
                 [0.4288, 0.4232, 0.3674, 0.3463],
                 [0.2227, 0.2234, 0.2463, 0.1905]],
        "unit": [[0.00486, 0.008945, 0.02466, 0.06597],
                 [0.002739, 0.004277, 0.01746, 0.06032],
                 [0.002462, 0.003728, 0.0169, 0.05965],
                 [0.002331, 0.003396, 0.01572, 0.05872],
                 [0.00161, 0.002773, 0.01469, 0.06203]]},
}
_SEVERITY = ("mild", "moderate", "severe")


def base_preset(name: str, defocus_px: float = 0.0, noise_scale: float = 1.0) -> Preset:
    """Preset `name` at one defocus radius (photo pixels, no motion) and its sensor noise (the middle of its
    ranges) times `noise_scale`, at a fixed scale (`COVERAGE`), small tilt and its middle JPEG quality."""
    p = get_preset(name)
    shot, read = noise_scale * float(np.mean(p.noise_shot)), noise_scale * float(np.mean(p.noise_read))
    q = int(round(float(np.mean(p.jpeg_quality))))
    return replace(p, name=f"profile ({name})", coverage=(COVERAGE, COVERAGE), tilt_deg=TILT_DEG,
                   defocus_px=(defocus_px, defocus_px), motion_px=(0.0, 0.0), noise_shot=(shot, shot),
                   noise_read=(read, read), jpeg_quality=(q, q))


def reference_table(seeds=(200, 201, 202), defocus=(0.0, 0.75, 1.5, 2.5, 4.0), noise=(1.0, 4.0, 16.0, 64.0),
                    presets=_SEVERITY, log=None) -> dict:
    """Measure the chart through `base_preset(name, d, k)` on the grid defocus x noise: {name: {"defocus",
    "noise", "mtf50", "gain", "unit"}}, each measure a (len(defocus), len(noise)) list of medians over
    `seeds` (the value of `TABLE`). Minutes: 3 presets x 20 cells x 3 seeds photos of the chart."""
    import cv2

    from .calibrate import calibrate_image
    from .sheet import chart_sheet
    from .simulate import simulate

    sheet = chart_sheet(2, caption=False)
    out = {}
    for name in presets:
        grid = np.zeros((3, len(defocus), len(noise)))
        for i, d in enumerate(defocus):
            for j, k in enumerate(noise):
                vals = []
                for s in seeds:
                    data, _, _ = simulate(sheet, base_preset(name, d, k), s)
                    prof = calibrate_image(cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR))
                    vals.append([prof["mtf50"], prof["channel"]["gain"], prof["channel"]["unit"]])
                grid[:, i, j] = np.exp(np.median(np.log(np.maximum(vals, 1e-9)), 0))
                if log:
                    log(f"{name} defocus {d} noise x{k}: " + ", ".join(f"{v:.4g}" for v in grid[:, i, j]))
        out[name] = {"defocus": list(defocus), "noise": list(noise),
                     **{key: [[float(f"{v:.4g}") for v in row] for row in grid[n]]
                        for n, key in enumerate(("mtf50", "gain", "unit"))}}
    return out


def _measures(profile: dict) -> np.ndarray:
    """log(mtf50, channel gain, channel unit) of a profile (`load_profile`'s dict); UserError (one line) when
    one is missing or not a finite number > 0."""
    from snapshot3d.errors import UserError

    ch = profile.get("channel") if isinstance(profile.get("channel"), dict) else {}
    vals = [profile.get("mtf50"), ch.get("gain"), ch.get("unit")]
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v) and v > 0 for v in vals):
        raise UserError("malformed channel profile (mtf50, channel gain and channel unit must be finite numbers > 0)")
    return np.log(np.asarray(vals, np.float64))


def _bilinear(grid: np.ndarray, dg: np.ndarray, lk: np.ndarray, d: np.ndarray, k: np.ndarray) -> np.ndarray:
    """grid (len(dg), len(lk)) at points (d, k) (arrays of one shape; k in log), clamped to the table."""
    i = np.clip(np.searchsorted(dg, d) - 1, 0, len(dg) - 2)
    j = np.clip(np.searchsorted(lk, k) - 1, 0, len(lk) - 2)
    a = np.clip((d - dg[i]) / (dg[i + 1] - dg[i]), 0, 1)
    b = np.clip((k - lk[j]) / (lk[j + 1] - lk[j]), 0, 1)
    return ((1 - a) * (1 - b) * grid[i, j] + a * (1 - b) * grid[i + 1, j] + (1 - a) * b * grid[i, j + 1]
            + a * b * grid[i + 1, j + 1])


def profile_preset(profile: dict) -> tuple[Preset, dict]:
    """A `simulate` preset for a channel profile (see the module doc), and what was solved: {"base",
    "defocus_px", "noise_scale", "expected": the table's mtf50, gain and unit there, "clamped": the measures
    more than 10 % from the profile's (the profile lies beyond what the simulator's preset reaches)}."""
    target = _measures(profile)
    name = profile["nearest_preset"]
    t = TABLE[name]
    dg, lk = np.asarray(t["defocus"], np.float64), np.log(np.asarray(t["noise"], np.float64))
    grids = [np.log(np.asarray(t[key], np.float64)) for key in _KEYS]
    d, k = np.meshgrid(np.linspace(dg[0], dg[-1], 161), np.linspace(lk[0], lk[-1], 121), indexing="ij")
    fit = [_bilinear(g, dg, lk, d, k) for g in grids]
    cost = sum(((f - x) / _SPREAD[key]) ** 2 for f, x, key in zip(fit, target, _KEYS))
    at = np.unravel_index(int(np.argmin(cost)), cost.shape)
    expected = {key: float(np.exp(f[at])) for key, f in zip(_KEYS, fit)}
    clamped = [key for key, x in zip(_KEYS, target) if abs(np.log(expected[key]) - x) > np.log(1.1)]
    info = {"base": name, "defocus_px": round(float(d[at]), 3), "noise_scale": round(float(np.exp(k[at])), 3),
            "expected": {key: round(v, 5) for key, v in expected.items()}, "clamped": clamped}
    return base_preset(name, float(d[at]), float(np.exp(k[at]))), info


def severity_position(profile: dict) -> float:
    """Where the profile lies on the severity axis, mild = 0, moderate = 1, severe = 2: its log(mtf50, gain,
    unit) projected onto the path through the presets' reference means (`PRESET_REFERENCE`), each measure in
    units of its spread (the mean over the presets), clamped to the path's ends."""
    x = _measures(profile)
    ref = np.array([[m for m, _ in PRESET_REFERENCE[n]] for n in _SEVERITY])
    sd = np.array([[s for _, s in PRESET_REFERENCE[n]] for n in _SEVERITY]).mean(0)
    best = (np.inf, 0.0)
    for i in range(len(_SEVERITY) - 1):
        a, b = ref[i] / sd, ref[i + 1] / sd
        s = float(np.clip(np.dot(x / sd - a, b - a) / np.dot(b - a, b - a), 0.0, 1.0))
        dist = float(np.sum((x / sd - a - s * (b - a)) ** 2))
        best = min(best, (dist, i + s))
    return best[1]


def reading_reference(seeds=range(100, 112), preset: str = "moderate") -> tuple[float, float]:
    """The median `print_channel` (gain, unit) the chart reads on photos of `preset` (the value of
    `MODERATE_READING`; 12 photos, about a minute)."""
    import cv2

    from .calibrate import calibrate_image
    from .sheet import chart_sheet
    from .simulate import simulate

    sheet, vals = chart_sheet(2, caption=False), []
    for s in seeds:
        prof = calibrate_image(cv2.imdecode(np.frombuffer(simulate(sheet, preset, s)[0], np.uint8), cv2.IMREAD_COLOR))
        vals.append([prof["print_channel"]["gain"], prof["print_channel"]["unit"]])
    g, u = np.median(vals, 0)
    return float(g), float(u)


def profile_channel(profile: dict, reference=None):
    """The print channel's model (`print_channel.ChannelModel`) a profile implies: `reference` (default the
    budget's `moderate` model, `train.field.curves.print_channel`) times the profile's `print_channel` over
    `MODERATE_READING`. Returns (model, info) with info {"nearest_preset", "severity_position", "gain",
    "unit"}. UserError (one line) for a profile without a valid `print_channel` (written before it was)."""
    from snapshot3d.codecs.print_channel import ChannelModel
    from snapshot3d.errors import UserError

    pc = profile.get("print_channel")
    vals = [pc.get("gain"), pc.get("unit")] if isinstance(pc, dict) else []
    if len(vals) != 2 or not all(isinstance(v, (int, float)) and np.isfinite(v) and v > 0 for v in vals):
        raise UserError("the channel profile has no print_channel (gain and unit > 0): run 'snapshot3d calibrate' "
                        "again on a photo of a new chart")
    if reference is None:
        from snapshot3d.paths import asset

        ch = json.loads(asset("budget-curves.json").read_text())["print"]["channel"]
        reference = ChannelModel(float(ch["gain"]), float(ch["unit"]))
    gain = reference.gain * vals[0] / MODERATE_READING[0]
    unit = reference.unit * vals[1] / MODERATE_READING[1]
    info = {"nearest_preset": profile["nearest_preset"], "severity_position": round(severity_position(profile), 3),
            "gain": round(gain, 4), "unit": round(unit, 4)}
    return ChannelModel(gain, unit), info
