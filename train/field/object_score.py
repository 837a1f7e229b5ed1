"""How well a fit of a capture holds the object alone (issue 40's measures), against the capture's ground truth:
the object's true masks (undistorted as the loader reads them) and its true box."""
from __future__ import annotations

import cv2
import numpy as np
import torch

from snapshot3d.carve import grid_centres
from snapshot3d.posed import PosedImages

from .field import decode, sample_planes
from .render import occupancy_from_planes, render_pixels, render_rays
from .sampler import BoxFrame

__all__ = ["score_object", "opacity_outside", "outline_split", "inner_mask", "edge_split", "ground_pixels",
           "clean_ceiling", "density_share_outside_box"]

RING_PX = 2   # the outline's ring: the true mask's pixels within this many pixels of its edge
NEAR_GROUND = 2.0   # the ground near the object: its footprint (the true box's) this many times as wide about its centre


def _psnr(err: np.ndarray) -> float:
    """dB of squared errors `err` (any shape, values of [0, 1]^2); an empty set reads as perfect (100 dB)."""
    return -10 * np.log10(max(float(err.mean()), 1e-10)) if err.size else 100.0


def inner_mask(mask: np.ndarray, ring_px: int = RING_PX) -> np.ndarray:
    """mask (H, W) bool -> (H, W) bool, its pixels more than `ring_px` from its edge (the frame's border is not one)."""
    return cv2.erode(mask.astype(np.uint8), np.ones((2 * ring_px + 1,) * 2, np.uint8), borderValue=1) > 0


def outline_split(rgb: np.ndarray, acc: np.ndarray, gt: np.ndarray, mask: np.ndarray, ring_px: int = RING_PX,
                  inner: np.ndarray | None = None) -> dict:
    """One view: rgb, gt (H, W, 3) RGB [0, 1], acc (H, W) the planes' opacity, mask (H, W) bool the object's true
    mask -> object_ring_psnr: dB over the mask's pixels within `ring_px` of its edge (where rays that graze the
    object pass); object_inner_psnr: dB over the rest of the mask; object_coverage: mean opacity inside the mask
    (1: the planes cover all of the object; lower: parts of it are explained by the background or left empty).
    `inner`: `inner_mask(mask, ring_px)` when the caller has it already."""
    inner = inner_mask(mask, ring_px) if inner is None else inner
    err = (rgb - gt) ** 2
    return {"object_ring_psnr": _psnr(err[mask & ~inner]), "object_inner_psnr": _psnr(err[inner]),
            "object_coverage": float(acc[mask].mean()) if mask.any() else 1.0}


def ground_pixels(c2w: np.ndarray, intrinsics, width: int, height: int, ground_z: float,
                  footprint: np.ndarray | None = None) -> np.ndarray:
    """One camera c2w (4, 4) OpenGL, intrinsics (fx, fy, cx, cy) pixels (centres at +0.5), in a z-up world whose
    ground is the plane z = ground_z -> (H, W) bool: the pixels whose ray descends to that plane in front of the
    camera, and with `footprint` (2, 2) [[x0, y0], [x1, y1]] meets it inside that rectangle."""
    from snapshot3d.cameras import pixel_rays

    o, d = (a.astype(np.float64) for a in pixel_rays(np.asarray(c2w, np.float64), *(float(v) for v in intrinsics),
                                                    width, height))
    down = (d[:, 2] < -1e-9) & (o[:, 2] > ground_z)
    if footprint is not None:
        t = np.where(down, (ground_z - o[:, 2]) / np.where(down, d[:, 2], -1.0), 0.0)
        q = o[:, :2] + t[:, None] * d[:, :2]
        down &= np.all((q >= footprint[0]) & (q <= footprint[1]), axis=1)
    return down.reshape(height, width)


def edge_split(acc: np.ndarray, mask: np.ndarray, near: np.ndarray) -> dict:
    """One view: acc (H, W) the planes' opacity, mask (H, W) bool the object's true mask, near (H, W) bool the
    pixels behind which lies the ground near the object (`ground_pixels` with a footprint) -> the pixels just
    outside the mask (its 8-neighbours), split by what lies behind them: edge_near_n, edge_far_n (counts: the
    ground near the object; the ground farther off, or the room), edge_near_sum, edge_far_sum (the planes' opacity
    summed over them). The mask keeps the pixels the object covers at least half of, so a fit whose outline is as
    sharp as the object's has little opacity there; a fat edge shows which side it grows into."""
    ring = (cv2.dilate(mask.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0) & ~mask
    on, off = ring & near, ring & ~near
    return {"edge_near_n": int(on.sum()), "edge_far_n": int(off.sum()),
            "edge_near_sum": float(acc[on].sum()), "edge_far_sum": float(acc[off].sum())}


def clean_ceiling(truth: PosedImages, clean: PosedImages, views=None) -> dict:
    """What a fit that renders the object alone perfectly would score against the photos: `clean` (the object over
    white, make-capture's gt/transforms_white.json) taken as the render, scored against `truth` (the masked photos)
    inside the true masks at `views` (default truth.test) -> object_psnr, object_ring_psnr, object_inner_psnr (the
    names of `score_object`'s, means over views); the photos' outline blends the room in, so this lies below a
    perfect score, most where the room is dark or busy."""
    views = truth.test if views is None else views
    obj, split = [], []
    for i in np.asarray(views):
        mask = truth.alpha[i] >= 0.5
        obj.append(_psnr(((clean.images[i] - truth.images[i]) ** 2)[mask]))
        split.append(outline_split(clean.images[i], np.ones(mask.shape, np.float32), truth.images[i], mask))
    return {"object_psnr": float(np.mean(obj)), **{k: float(np.mean([v[k] for v in split]))
                                                   for k in ("object_ring_psnr", "object_inner_psnr")}}


@torch.no_grad()
def density_share_outside_box(planes: torch.Tensor, decoder, box, true_box, res: int = 64) -> float:
    """Share of the planes' one-step opacity, summed over a res^3 grid of the fitted `box` (2, 3) world, that lies
    outside `true_box` (2, 3) world."""
    box, true_box = np.asarray(box, np.float64), np.asarray(true_box, np.float64)
    frame = BoxFrame.from_box(box, planes.device)
    pts = grid_centres(box, res).reshape(-1, 3)
    unit = torch.from_numpy(((pts - box.mean(0)) / ((box[1] - box[0]) / 2)).astype(np.float32)).to(planes.device)
    sigma = torch.cat([decode(sample_planes(planes, u), decoder)[0] for u in unit.split(1 << 16)])
    alpha = (1 - torch.exp(-sigma * frame.step)).cpu().numpy()
    outside = ~np.all((pts >= true_box[0]) & (pts <= true_box[1]), axis=1)
    return float(alpha[outside].sum() / max(alpha.sum(), 1e-12))


@torch.no_grad()
def opacity_outside(acc: np.ndarray, masks: np.ndarray, grow: int = 2) -> float:
    """acc (V, H, W) opacity in [0, 1], masks (V, H, W) bool -> the share of the opacity summed over all the views'
    pixels that falls outside the masks grown by `grow` pixels (a square of side 2 grow + 1); 0 with no opacity."""
    kernel = np.ones((2 * grow + 1, 2 * grow + 1), np.uint8)
    near = total = 0.0
    for a, m in zip(acc, masks):
        grown = cv2.dilate(m.astype(np.uint8), kernel) > 0 if grow > 0 else m.astype(bool)
        near, total = near + float(a[grown].sum()), total + float(a.sum())
    return float(1 - near / total) if total > 0 else 0.0


def score_object(planes: torch.Tensor, decoder, box, truth: PosedImages, true_box, views=None,
                 chunk: int = 8192, clean: PosedImages | None = None) -> dict:
    """planes (3, C, R, R) over world `box` (2, 3), rendered over white at `views` (default truth.test) of `truth`
    (the capture read with its true masks: alpha (N, H, W) coverage, images white outside the object) ->
    object_psnr: dB inside the true mask (alpha >= 0.5), mean over views;
    white_psnr: dB of the whole view against the object on white (floaters count);
    opacity_outside: share of the planes' opacity summed over the views' pixels that falls outside the mask;
    opacity_outside_2px: the same outside the mask grown by 2 pixels (edges and the mask's own rounding forgiven);
    object_ring_psnr, object_inner_psnr, object_coverage: `outline_split`'s, mean over views;
    edge_opacity_near, edge_opacity_far: the planes' mean opacity on the pixels just outside the true mask whose
    ray meets the ground (the plane of true_box's floor) near the object (within NEAR_GROUND times its footprint,
    where its shadow and a fit's floor band lie) and on the others (`edge_split`, pooled over views), and
    edge_near_share: the near ground's share of that opacity summed;
    density_outside_box: `density_share_outside_box` against `true_box`;
    with `clean` (the object alone over white at the same frames, make-capture's gt/transforms_white.json):
    object_clean_psnr, object_clean_ring_psnr, object_clean_inner_psnr, the same in the same masks against it
    (the photos' outline blends the object with the room, which a fit of the object alone does not carry)."""
    if truth.alpha is None:
        raise ValueError("score_object needs the capture read with its true masks")
    views = truth.test if views is None else views
    frame = BoxFrame.from_box(box, planes.device)
    occ = occupancy_from_planes(planes, decoder, frame)
    views = np.asarray(views)
    rgbs, accs = render_pixels(lambda o, d: render_rays(planes, decoder, frame, occ, o, d)[:2], frame, truth.c2w[views],
                               truth.intrinsics[views], truth.width, truth.height, chunk)
    obj, white, split, edges, acc_in, acc_near, acc_all = [], [], [], [], 0.0, 0.0, 0.0
    tb = np.asarray(true_box, np.float64)
    centre, half = tb[:, :2].mean(0), NEAR_GROUND * (tb[1, :2] - tb[0, :2]) / 2
    footprint = np.stack([centre - half, centre + half])
    for i, rgb, acc in zip(views, rgbs, accs):
        mask, gt = truth.alpha[i] >= 0.5, truth.images[i]
        err = (rgb - gt) ** 2
        obj.append(_psnr(err[mask]))
        white.append(_psnr(err))
        inner = inner_mask(mask)
        split.append(outline_split(rgb, acc, gt, mask, inner=inner))
        if clean is not None:
            on_white = outline_split(rgb, acc, clean.images[i], mask, inner=inner)
            split[-1].update({"object_clean_psnr": _psnr(((rgb - clean.images[i]) ** 2)[mask]),
                              "object_clean_ring_psnr": on_white["object_ring_psnr"],
                              "object_clean_inner_psnr": on_white["object_inner_psnr"]})
        edges.append(edge_split(acc, mask, ground_pixels(truth.c2w[i], truth.intrinsics[i], truth.width, truth.height,
                                                         float(tb[0, 2]), footprint)))
        near = cv2.dilate(mask.astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
        acc_in, acc_near, acc_all = acc_in + float(acc[mask].sum()), acc_near + float(acc[near].sum()), \
            acc_all + float(acc.sum())
    return {"object_psnr": float(np.mean(obj)), "white_psnr": float(np.mean(white)),
            "opacity_outside": float(1 - acc_in / max(acc_all, 1e-12)),
            "opacity_outside_2px": float(1 - acc_near / max(acc_all, 1e-12)),
            **{k: float(np.mean([v[k] for v in split])) for k in split[0]}, **_edges(edges),
            "density_outside_box": density_share_outside_box(planes, decoder, box, true_box)}


def _edges(views: list[dict]) -> dict:
    """`edge_split`s of several views -> edge_opacity_near, edge_opacity_far (mean opacity, pooled; 0 where a side
    has no pixel) and edge_near_share (the near ground's share of the opacity summed on both)."""
    tot = {k: sum(v[k] for v in views) for k in views[0]}
    both = tot["edge_near_sum"] + tot["edge_far_sum"]
    return {"edge_opacity_near": tot["edge_near_sum"] / max(tot["edge_near_n"], 1),
            "edge_opacity_far": tot["edge_far_sum"] / max(tot["edge_far_n"], 1),
            "edge_near_share": tot["edge_near_sum"] / both if both > 0 else 0.0}
