"""`fit --budget auto --medium M` (DESIGN section 4): fit a ladder of plane sizes and keep the one that gives
the best `e2e_psnr` expected through medium M; the smallest rung within `tolerance_db` of the best wins.

- `print`: each rung's own planes go through the print channel's model (`snapshot3d.codecs.print_channel`, its
  constants measured by `bench print-predict` and kept in `snapshot3d/assets/budget-curves.json`):
  embedded in each of `PREDICT_HOSTS`, read with the model's gain and noise, restored, and scored
  against the held-out views (the median over the hosts). The codec's share of the loss depends on the
  scene's own plane spectrum, which a curve of payload size cannot know (lego's 48x4 restores 4 dB
  below spot's at the same payload).
- `file` (and `print` without a channel model): the field's own error (held-out `field_psnr`) plus what
  the medium's codec loses at that payload (its `restore_psnr`, read from the codec bench's curve of
  payload size against restore fidelity, `budget-curves.json`), added as mean square errors.

The largest rung is fitted from scratch; each smaller rung starts from the largest planes, area-
downsampled to its resolution with the leading channels kept (the decoder is trained with nested
channels, so leading channels carry the most), and is fine-tuned for a fraction of the steps. With the print
medium the chosen rung, when it is not the largest, is then fitted again from scratch, and the better of the two
by the channel's model is kept (docs/fitting.md, "A head of the scene's own").
"""
from __future__ import annotations

import time
from dataclasses import replace

import numpy as np
import torch
import torch.nn.functional as F

from snapshot3d.posed import PosedImages
from snapshot3d.scene import dequantize_planes

from .config import LADDER, LADDER_PRINT, FitConfig
from .curves import CURVES_FILE, PREDICT_HOSTS, codec_psnr, print_channel
from .ending import Ending, ending_noise, ending_views
from .evaluate import evaluate_planes
from .fit import fit, hull_grid
from .head import with_head
from .object_score import opacity_outside

__all__ = ["fit_ladder", "choose_rung", "codec_psnr", "expected_e2e", "codec_share", "ladder_for", "print_channel",
           "predicted_e2e", "CURVES_FILE", "PREDICT_HOSTS"]

def predicted_e2e(planes: np.ndarray, decoder, posed: PosedImages, channel, hosts=PREDICT_HOSTS, seed: int = 0,
                  **scoring) -> float:
    """The e2e_psnr (held-out views) expected of planes (3, C, R, R) printed and captured: the median over
    `hosts` of one draw of the channel model each. `scoring`: `evaluate_planes`'s background, samples, masks."""
    from snapshot3d.codecs.print_channel import predicted_planes
    from snapshot3d.scanner.backgrounds import load_host
    from snapshot3d.scene import quantize_planes

    rng = np.random.default_rng(seed)
    scores = [evaluate_planes(dequantize_planes(quantize_planes(predicted_planes(load_host(h), planes, channel, rng))),
                              decoder, posed, with_ssim=False, **scoring)["field_psnr"] for h in hosts]
    return float(np.median(scores))


def codec_share(field_psnr: float, e2e_psnr: float) -> float:
    """The codec's restore_psnr implied by a field's own error and the e2e it ends at (inverse of
    `expected_e2e`; 99 dB when the codec lost nothing measurable)."""
    rest = 10 ** (-e2e_psnr / 10) - 10 ** (-field_psnr / 10)
    return float(min(-10 * np.log10(rest), 99.0)) if rest > 0 else 99.0


def ladder_for(medium: str | None):
    """The plane sizes a medium's ladder tries (None: the fixed-budget ladder of the field alone)."""
    return LADDER_PRINT if medium == "print" else LADDER


def expected_e2e(field_psnr: float, codec_db: float) -> float:
    """The e2e_psnr of a field of `field_psnr` carried with a codec of `codec_db`: their errors add."""
    return float(-10 * np.log10(10 ** (-field_psnr / 10) + 10 ** (-codec_db / 10)))


def choose_rung(rungs: list[dict], tolerance_db: float = 0.5, key: str = "field_psnr") -> int:
    """Index of the smallest rung (by scene_kb) whose `key` (field_psnr, or e2e_expected) is within
    `tolerance_db` of the best."""
    best = max(r[key] for r in rungs)
    ok = [i for i, r in enumerate(rungs) if r[key] >= best - tolerance_db]
    return min(ok, key=lambda i: rungs[i]["scene_kb"])


def fit_ladder(posed: PosedImages, decoder, cfg: FitConfig, ladder=None, tolerance_db: float = 0.5,
               finetune_fraction: float = 0.4, log=print, progress_factory=None, device=None, medium: str | None = None,
               channel=None):
    """Returns (chosen rung index, rungs): each rung a dict with plane_res, plane_channels, scene_kb,
    field_psnr, field_ssim, fit_seconds and its `codes`; with a `medium`, also codec_psnr (what its codec
    costs this rung) and e2e_expected, by which the rung is chosen (print: predicted from the rung's own
    planes through `channel`, a `print_channel.ChannelModel`, by default the `moderate` one of budget-curves.json
    (a measured one: `scanner.profile_channel.profile_channel`); the curve's value kept as codec_psnr_curve).
    With the print medium, a chosen rung that was fine-tuned from the largest one is fitted again from scratch (all
    the steps, the full learning rate), and that fit is kept when its expected e2e is no worse (`refit` in the
    rung: spot's 16x4 rung gained 0.65 dB of field and 0.3-0.5 dB through `mild` and `moderate` photos)."""
    ladder = ladder or ladder_for(medium)
    channel = (channel or print_channel()) if medium == "print" else None
    hull = hull_grid(posed)
    rungs, big = [], None
    if channel is not None and cfg.ending == "auto" and cfg.background != "outer" and cfg.qat_fraction > 0:
        log(f"print budget: each rung's last {cfg.qat_fraction:.0%} of steps runs twice, plain and through the print "
            f"channel's noise, and the ending expected better through a print is kept (--ending plain: once)")
    rung_fit = _RungFit(posed, decoder, cfg, hull, device, medium, channel, progress_factory)
    for res, ch in ladder:
        init = None if big is None else F.interpolate(big[:, :ch], size=(res, res), mode="area")
        rung, codes = rung_fit(res, ch, init, finetune_fraction)
        if big is None:
            big = torch.from_numpy(dequantize_planes(codes))
        rungs.append(rung)
        log(_rung_line(rung, medium, channel))
    chosen = choose_rung(rungs, tolerance_db, "e2e_expected" if medium else "field_psnr")
    if channel is not None and chosen > 0:   # the chosen rung from scratch: its fine-tune starts from a poorer point
        rung = rungs[chosen]
        again, _ = rung_fit(rung["plane_res"], rung["plane_channels"], None, 1.0, " from scratch")
        floaters = refit_floaters(cfg, rungs[0], rung, again)
        kept = refit_kept(cfg, again["e2e_expected"], rung["e2e_expected"], floaters)
        refit = {"field_psnr": again["field_psnr"], "e2e_expected": again["e2e_expected"], "kept": kept,
                 "fit_seconds": again["fit_seconds"], **({"floaters": floaters} if floaters else {})}
        rungs[chosen] = {**(again if kept else rung), "refit": refit,
                         "fit_seconds": round(rung["fit_seconds"] + again["fit_seconds"], 1)}
        log(f"ladder R={rung['plane_res']} C={rung['plane_channels']} again from scratch: field_psnr "
            f"{again['field_psnr']:.2f} dB, e2e expected {again['e2e_expected']:.2f} dB "
            f"({'kept' if kept else 'not kept'}: the fine-tuned rung expected {rung['e2e_expected']:.2f}"
            + (f"; opacity outside the largest rung's outline {floaters['again']:.2%} against {floaters['tuned']:.2%}"
               if floaters else "") + f"), {again['fit_seconds']:.0f} s")
    return chosen, rungs


def object_alone(cfg: FitConfig) -> bool:
    """Whether a fit of `cfg` ends on the object alone (the background model, then `--object-steps`)."""
    return cfg.background == "outer" and cfg.object_steps > 0


def refit_floaters(cfg: FitConfig, largest: dict, tuned: dict, again: dict) -> dict | None:
    """For the object alone (`object_alone`): the share of the fine-tuned and the from-scratch rungs' opacity at the
    held-out views outside the largest rung's outline (its opacity >= one half) grown by 2 px, as {"tuned": share,
    "again": share}; None for any other fit (no opacity kept)."""
    if not object_alone(cfg) or any("_opacity" not in r for r in (largest, tuned, again)):
        return None
    return {k: round(opacity_outside(r["_opacity"], largest["_masks"]), 4) for k, r in (("tuned", tuned),
                                                                                     ("again", again))}


def refit_kept(cfg: FitConfig, again: float, tuned: float, floaters: dict | None = None) -> bool:
    """Whether the chosen rung fitted again from scratch is kept, its expected e2e `again` against the fine-tuned
    rung's `tuned` (dB). --refit always: kept; model: where it is expected no worse; auto: as model, and for the
    object alone also where it leaves less opacity outside the largest rung's outline (`refit_floaters`). The
    model, scored on the object's own pixels, does not see the outline: on spot's print chains the fit from scratch
    left 0.19 to 0.84 points fewer floaters decoded, where on the bunny's it left 3 points more
    (docs/capture-record.md, "The fit from scratch kept only where it leaves fewer floaters")."""
    if cfg.refit == "always" or again >= tuned:
        return True
    return (cfg.refit == "auto" and object_alone(cfg) and floaters is not None
            and floaters["again"] < floaters["tuned"])


class _RungFit:
    """One rung of the ladder: fitted (from `init` planes, fine-tuned for `fraction` of the steps at half the
    learning rate; or, with no `init`, from scratch) and scored -> (the rung's dict, its codes)."""

    def __init__(self, posed, decoder, cfg, hull, device, medium, channel, progress_factory):
        self.posed, self.decoder, self.cfg, self.hull, self.device = posed, decoder, cfg, hull, device
        self.medium, self.channel, self.bars = medium, channel, progress_factory

    def __call__(self, res: int, ch: int, init, fraction: float, label: str = "") -> tuple[dict, np.ndarray]:
        from snapshot3d.scene import Orbit, Scene
        cfg, posed, channel = self.cfg, self.posed, self.channel
        rcfg = replace(cfg, plane_res=res, plane_channels=ch)
        if init is not None:
            rcfg = replace(rcfg, steps=max(min(100, cfg.steps), int(cfg.steps * fraction)), lr=cfg.lr / 2,
                           occ_warmup=0)
        t0 = time.perf_counter()
        ending = None
        if channel is not None and cfg.ending == "auto":   # train/field/ending.py
            ending = Ending(ending_noise(res, ch, channel, self.device, cfg.channel_noise),
                            lambda planes, dec: predicted_e2e(planes, dec, posed, channel, views=ending_views(posed)))
        bars = self.bars
        res_ = fit(posed, self.decoder, rcfg, init_planes=init, hull=self.hull, device=self.device,
                   progress=bars(f"R={res} C={ch}{label}", rcfg.steps) if bars else None,
                   object_bar=(lambda n: bars(f"R={res} C={ch}{label} object alone", n)) if bars else None,
                   ending=ending)
        seconds = time.perf_counter() - t0
        scoring = {"background": res_.state.background, "samples": cfg.background_samples}
        own = with_head(self.decoder, res_.head)   # the scene's own head, as carried, when it has one
        ev = evaluate_planes(dequantize_planes(res_.codes), own, posed, **scoring)
        scoring["masks"] = ev.get("masks")   # a print's restored planes are scored on the field's own object pixels
        kb = Scene(codes=res_.codes, box=posed.box, orbit=Orbit(radius=1.0), head=res_.head).scene_kb
        rung = {"plane_res": res, "plane_channels": ch, "scene_kb": round(kb, 2),
                "field_psnr": round(ev["field_psnr"], 3), "field_ssim": round(ev["field_ssim"], 4),
                "fit_seconds": round(seconds, 1), "codes": res_.codes, "head": res_.head,
                **({"ending": res_.ending} if res_.ending else {})}
        if "opacity" in ev:   # the planes' own opacity at the held-out views, for the refit's floaters (fit_ladder)
            rung.update(_opacity=ev["opacity"], _masks=ev["masks"])
        if self.medium is not None:
            c = codec_psnr(self.medium, int(res_.codes.size))
            rung.update(codec_psnr=round(c, 3), e2e_expected=round(expected_e2e(ev["field_psnr"], c), 3))
            if channel is not None:  # the scene's own planes through the print channel's model
                e2e = predicted_e2e(dequantize_planes(res_.codes), own, posed, channel, **scoring)
                rung.update(codec_psnr_curve=rung["codec_psnr"], e2e_expected=round(e2e, 3),
                            codec_psnr=round(codec_share(ev["field_psnr"], e2e), 3))
        return rung, res_.codes


def _rung_line(rung: dict, medium: str | None, channel) -> str:
    """The log line of a fitted rung."""
    tail = ""
    if rung.get("ending"):
        e = rung["ending"]["e2e_expected"]
        tail = (f", last phase {'through the channel' if rung['ending']['kept'] == 'channel' else 'plain'} "
                f"(expected {e['channel'] - e['plain']:+.2f} dB through the channel's noise)")
    return (f"ladder R={rung['plane_res']} C={rung['plane_channels']}: {rung['scene_kb']:.1f} kB, field_psnr "
            f"{rung['field_psnr']:.2f} dB"
            + (f", codec ({medium}{', this scene' if channel is not None else ''}) {rung['codec_psnr']:.2f} dB, "
               f"e2e expected {rung['e2e_expected']:.2f} dB" if medium else "") + f"{tail}, {rung['fit_seconds']:.0f} s")
