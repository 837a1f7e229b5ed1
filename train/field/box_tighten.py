"""The automatic box tightened (fit --background outer with --box auto): from the training photos' sparse points
when they show a ground with an object on it (`snapshot3d/sparse_box.py`), else from the learned density: a short fit
with the background model in the box the cameras' overlap gives (`snapshot3d/auto_box.py`), then, from the
planes' density on a grid over that box, the ground, when most cameras look down (`box_from_density`): the box
is cut at its top, so that the floor is left to the background model and the planes hold what stands on it. The
fit then starts again in the new box. With cfg.tighten_sides (the default) the sides and the top are cut too,
round the cells denser than SOLID with a wide margin: after a short fit the density is diffuse, and a tight cut
would take part of the object (bench capture-background: fewer floaters on spot and duck, docs/capture.md).
With the ground found, `object_box` then cuts the box round the object's cells of a longer fit in it
(cfg.object_box of the steps), which are tight enough to cut round: the planes' texels go to the object."""
from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from snapshot3d.posed import PosedImages

from .config import FitConfig
from .render import cell_alpha

__all__ = ["tighten_box", "box_from_density", "object_box", "cells_box", "PREFIT_FRACTION", "OBJECT_MARGIN"]

PREFIT_FRACTION = 0.3   # of the fit's steps, spent on the short fit in the first box
GRID = 64
GROUND_RATIO = 2.0      # a ground layer's mean opacity over the median layer's
TOP_SHARE = 0.8
GROUND_COVER = 0.5
SOLID = 0.5             # with cfg.tighten_sides: cells above this opacity are the object's candidates ...
SOLID_SHARE = 0.02      # ... the sides and top are cut where this share of them lies beyond, on each side ...
SIDE_MARGIN = 0.25      # ... and moved out again by this fraction of what is kept, plus SIDE_CELLS cells
SIDE_CELLS = 2
OBJECT_MARGIN = 2       # cells of the object-box fit's grid round the object's cells (which are grown already)


def box_from_density(alpha: np.ndarray, box: np.ndarray, looks_down: bool,
                     sides: bool = False) -> tuple[np.ndarray, float | None]:
    """alpha (G, G, G) [ix, iy, iz] opacity over one cell of a grid over world `box` (2, 3) -> the box (2, 3)
    float32 cut at the ground, and the ground's height (None when not looked for or not found). The ground is the
    highest layer of the lower half within TOP_SHARE of the most opacity there, when that most is more than
    GROUND_RATIO times the median layer's and the layer is denser than GROUND_RATIO times the median cell over
    more than GROUND_COVER of the footprint: a floor spans the whole footprint, an object a part of it.
    With `sides`, the box's sides and top are then cut too (`_sides_and_top`)."""
    out, ground = _ground(alpha, box, looks_down)
    if sides:
        k = 0 if ground is None else int(round((ground - box[0, 2]) / (box[1, 2] - box[0, 2]) * alpha.shape[2]))
        out = _sides_and_top(alpha, box, out, k)
    return out, ground


def _sides_and_top(alpha: np.ndarray, box: np.ndarray, out: np.ndarray, k: int) -> np.ndarray:
    """`out` (2, 3) with its sides and top cut to the cells above layer k denser than SOLID: on each axis,
    between the SOLID_SHARE and 1 - SOLID_SHARE quantiles of their count, widened by SIDE_MARGIN of that span
    and SIDE_CELLS cells; the floor (z min) is kept."""
    solid = alpha[:, :, k:] > SOLID
    if solid.sum() < 8:
        return out
    out = out.copy()
    for ax in range(3):
        prof = solid.sum(axis=tuple(j for j in range(3) if j != ax)).astype(np.float64)
        cum = np.cumsum(prof) / prof.sum()
        lo, hi = float(np.searchsorted(cum, SOLID_SHARE)), float(np.searchsorted(cum, 1 - SOLID_SHARE)) + 1
        if ax == 2:
            lo, hi = lo + k, hi + k
        pad = SIDE_MARGIN * (hi - lo) + SIDE_CELLS
        cell = (box[1, ax] - box[0, ax]) / alpha.shape[ax]
        if ax < 2:
            out[0, ax] = max(out[0, ax], box[0, ax] + max(0.0, lo - pad) * cell)
        out[1, ax] = min(out[1, ax], box[0, ax] + min(float(alpha.shape[ax]), hi + pad) * cell)
    return out


def _ground(alpha: np.ndarray, box: np.ndarray, looks_down: bool) -> tuple[np.ndarray, float | None]:
    out = box.astype(np.float32).copy()
    if not looks_down:
        return out, None
    g = alpha.shape[2]
    layers = alpha.mean(axis=(0, 1))
    lower = layers[:g // 2]
    if not lower.max() > GROUND_RATIO * max(float(np.median(layers)), 1e-6):
        return out, None
    k = int(np.nonzero(lower >= TOP_SHARE * lower.max())[0].max())   # the top of a floor that is a slab
    if not np.mean(alpha[:, :, k] > GROUND_RATIO * max(float(np.median(alpha)), 1e-6)) > GROUND_COVER:
        return out, None
    ground = float(box[0, 2] + (k + 1) * (box[1, 2] - box[0, 2]) / g)
    out[0, 2] = ground
    return out, ground


def tighten_box(posed: PosedImages, decoder, cfg: FitConfig,
                device=None) -> tuple[np.ndarray, dict, np.ndarray | None]:
    """The box of `posed` cut at the ground and round the object from the training photos' sparse points
    (`snapshot3d.sparse_box`, with cfg.sparse_box and cameras that look down), else tightened from a short fit with
    the background model (PREFIT_FRACTION of cfg.steps, at least 10) -> (box (2, 3) float32 world, info for the
    report: ground_z, and the sparse points' counts or the pre-fit's steps; the training views' poses (T, 4, 4)
    float32 after the sparse box's bundle adjustment with cfg.bundle "fit", where it ran and the box came from the
    sparse points, else None). cfg.bundle "auto" is resolved by `fit_scene` (fit where the poses are refined); here
    it counts as off."""
    t0 = time.perf_counter()
    looks_down = bool(np.mean(-posed.c2w[posed.train, 2, 2] < 0) > 0.5)   # optical axes (-z) pointing down
    info = {"first_box": np.round(posed.box, 4).tolist(), "sides_cut": bool(cfg.tighten_sides)}
    if cfg.sparse_box and looks_down:
        from snapshot3d.sparse_box import SparseBoxConfig, sparse_box
        t = posed.train
        box, found, c2w = sparse_box(posed.images[t], posed.c2w[t], posed.intrinsics[t], posed.box,
                                     SparseBoxConfig(bundle=cfg.bundle in ("fit", "box")))
        info.update(found, sparse_seconds=round(time.perf_counter() - t0, 1))
        if box is not None and cfg.ground_sweep and found.get("ground_pixels") is not None:
            info.update(_swept(posed, c2w, found))
        if box is not None:
            if not cfg.tighten_sides:   # the floor alone
                floor, box = box[0, 2], np.array(posed.box, np.float32)
                box[0, 2] = floor
            # the floor is lifted over the ground the points found; the ground's texture lies that far under it
            depth = max(0.0, float(box[0, 2]) - found["sparse_ground"])
            return box, {**info, "ground_z": float(box[0, 2]), "ground_depth": round(depth, 4),
                         "box_from": "sparse points", "prefit_steps": 0,
                         "prefit_seconds": 0.0}, (
                c2w.astype(np.float32) if cfg.bundle == "fit" and found.get("bundle", {}).get("adjusted") else None)
    return (*_tightened_by_prefit(posed, decoder, cfg, looks_down, info, device), None)


def _swept(posed: PosedImages, c2w: np.ndarray, found: dict) -> dict:
    """The sparse box's ground pixels with those the ground plane's sweep finds (`snapshot3d.ground_sweep`, fit
    --ground-sweep) -> info's ground_pixels (K, 3) (train frame, row, col) and ground_sweep_pixels (their count
    the sweep found)."""
    from snapshot3d.ground_sweep import ground_sweep

    t = posed.train
    dense = ground_sweep(posed.images[t], c2w, posed.intrinsics[t], found["ground_plane"], np.mean(posed.box, axis=0))
    both = np.unique(np.concatenate([np.asarray(found["ground_pixels"], np.int64), dense]), axis=0)
    return {"ground_pixels": both, "ground_sweep_pixels": int(len(dense))}


def _tightened_by_prefit(posed: PosedImages, decoder, cfg: FitConfig, looks_down: bool, info: dict,
                         device=None) -> tuple[np.ndarray, dict]:
    from .fit import fit
    t0 = time.perf_counter()
    # the penalties at the box's walls and floor are left to the fit in the new box: here they thin the floor,
    # which is then found too low (spot: z = -1.08 against -0.92) and left in the box
    pre = replace(cfg, steps=max(10, int(cfg.steps * PREFIT_FRACTION)), background="outer", qat_fraction=0.0,
                  channel_fraction=0.0, wall_weight=0.0, floor_weight=0.0,
                  object_steps=0.0)
    res = fit(posed, decoder, pre, device=device)
    alpha = cell_alpha(res.state.planes.planes.detach(), decoder, posed.box, GRID)
    box, ground = box_from_density(alpha, np.asarray(posed.box, np.float64), looks_down, cfg.tighten_sides)
    return box, {**info, "ground_z": None if ground is None else round(ground, 4), "box_from": "density",
                 "prefit_steps": pre.steps, "prefit_seconds": round(time.perf_counter() - t0, 1)}


def cells_box(cells: np.ndarray, box: np.ndarray, margin: int = OBJECT_MARGIN) -> np.ndarray:
    """cells (G, G, G) bool [ix, iy, iz] over world `box` (2, 3) -> (2, 3) float32, the box round the set cells
    widened by `margin` cells, inside `box`, its floor kept (the ground cut); `box` when no cell is set."""
    box = np.asarray(box, np.float64)
    if not cells.any():
        return box.astype(np.float32)
    g = np.array(cells.shape, np.float64)
    idx = np.nonzero(cells)
    lo = np.array([i.min() for i in idx], np.float64) - margin
    hi = np.array([i.max() for i in idx], np.float64) + 1 + margin
    cell = (box[1] - box[0]) / g
    out = np.stack([np.maximum(box[0], box[0] + lo * cell), np.minimum(box[1], box[0] + hi * cell)])
    out[0, 2] = box[0, 2]
    return out.astype(np.float32)


def object_box(posed: PosedImages, decoder, cfg: FitConfig, device=None) -> tuple[np.ndarray, dict, np.ndarray]:
    """The box of `posed` (already cut at the ground) cut round the object: a fit of cfg.object_box of the steps
    with the background model, the object's cells of its planes (`object_carve.object_cells`, as the object-alone
    step finds them), and `cells_box` round them -> (box (2, 3) float32 world, info for the report, the object's
    cells (GRID, GRID, GRID) bool [ix, iy, iz] over posed.box, which the ground rays spare with
    --seen-ground-spare: `seen_ground.clear_opacity`). After the pre-fit the density is too diffuse for a tight
    cut (docs/capture.md); after this longer fit the object's cells lie within a few cells of the object, and 16x4
    planes spread over a box 1.5 times too wide lose 1-2 dB."""
    from .fit import fit
    from .object_carve import object_cells
    t0 = time.perf_counter()
    # without the rays that show the ground: their penalty cost spot's frontal arc half its body in this short fit
    pre = replace(cfg, steps=max(10, round(cfg.steps * cfg.object_box)), background="outer", qat_fraction=0.0,
                  channel_fraction=0.0, object_steps=0.0, seen_ground_weight=0.0)
    res = fit(posed, decoder, pre, device=device)
    alpha, rgb = cell_alpha(res.state.planes.planes.detach(), decoder, posed.box, GRID, with_rgb=True)
    cells = object_cells(alpha, rgb)
    box = cells_box(cells, posed.box)
    return box, {"object_box_steps": pre.steps, "object_box_seconds": round(time.perf_counter() - t0, 1)}, cells
