"""The object alone, out of a fit with the background model (fit --background outer, cfg.object_steps): the planes
of such a fit still paint the ground's texture and the object's shadow in the lowest layers of the box, and a haze
round the object, all of which the background model would have had to hold in finer detail than it has. The
snapshot carries the planes alone, over white, so those would print as a dark slab under the object.

After the fit, `object_cells` finds the object's cells in a grid of the planes' one-cell opacities [ix, iy, iz] over
the box (z up, its floor cut at the ground by `box_tighten`): the solid cells (opacity above SOLID), without those in
the floor band (the lowest FLOOR_BAND of the box) over which nothing solid stands (no solid cell within REACH cells
sideways in the ABOVE layers just over the band: a leg or a body resting on the ground keeps its cells, the ground's
texture and the object's shadow round it do not), unless, given the cells' colours, they widen a base down
the band in the lower body's colour rather than the ground's (`_widened_base`: the bunny's haunches); of those,
the connected pieces at least KEEP_SHARE of the largest's size; then grown by NEAR cells, so that the object's
soft edge stays, but not into the floor band beyond what stands there. Of those, the floor band's cells outside
the photos' silhouettes in too many views go too (`silhouette.py`, cfg.object_silhouette: the skirt of shadow
under a belly, which stands under the object's own cells). `object_views` renders the training
views of the fitted planes with every other cell skipped, over white, at the poses the fit refined; where a view is
opaque its colour is the photo's (`photo_colours`): the planes of a fit with the ground in the box paint the ground's
texture into the object's colour too (the plane over the floor is shared by every height), which the photo does not
have. Their opacity is made solid about one half (`solid_cover`, cfg.object_opaque): where a ground of the object's
colour lies behind, the fit leaves the object partly see-through, and a real object is opaque; on a print's small
planes on a grid finer than the pixels, so that the outline stays anti-aliased (`subpixel_for`, cfg.object_subpixel). The planes are then
fitted to those views (from where
they are, DISTIL_LR) with the object's cells as their hull: the rays skip the other cells and the empty-space
penalty (`fit.empty_alpha`) drives their density to zero, so that the decode side, which finds its occupancy from
the planes alone, sees them empty too (`fit.fit` runs that fit). Fitting them with the cells cut while still
against the photos instead lost the legs and 3 to 4 dB on spot (docs/capture.md).
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from snapshot3d import formats
from snapshot3d.posed import PosedImages

__all__ = ["object_cells", "object_views", "band_vote", "halo_vote", "object_config", "photo_colours", "refined_c2w",
           "solid_cover", "PHOTO_RAMP", "SOLID", "FLOOR_BAND", "ABOVE", "REACH", "KEEP_SHARE", "NEAR",
           "TEACHER_SIZE", "DISTIL_LR", "STEP_DOWN", "KNN", "GROUND_LAYERS",
           "FOOTPRINT", "SEPARATE", "subpixel_for", "SUBPIXEL", "COARSE_RES"]

SOLID = 0.2         # one-cell opacity of an object's cell (0.5 cut half of a short fit's cloudy teapot)
FLOOR_BAND = 0.1    # of the box's height: where the ground's texture and the shadow are painted
ABOVE = 0.05        # of the box's height, just over the band: where what stands on the floor must be solid
REACH = 1           # cells sideways
KEEP_SHARE = 0.05   # connected pieces smaller than this share of the largest are floaters
NEAR = 3            # cells the object's cells are grown by (2 cut the teapot's spout and knob: -0.7 dB)
TEACHER_SIZE = 400  # longer side, pixels, of the views the planes are fitted to (the capture's when smaller)
DISTIL_LR = 0.03    # the planes' learning rate then, at the first step
PHOTO_RAMP = (0.5, 0.9)   # the view's opacity over which its colour gives way to the photo's
STEP_DOWN = 2       # cells sideways per layer by which a base may widen down through the floor band ...
KNN = 5             # ... where its colour is nearer the lower body's than the ground's, by the KNN-th nearest
GROUND_LAYERS = 2   # the lowest layers: outside what stands, their solid cells are the ground's colours
SEPARATE = 0.8      # the share of the ground's colours the test must tell from the body's (bunny 0.87)
FOOTPRINT = 3       # cells round the footprint of all that is solid above the band, which a base stays under
SUBPIXEL = 4        # --object-subpixel auto: the views made solid on a grid this much finer ...
COARSE_RES = 32     # ... where the planes are at most this many texels a side (the print's small rungs)


def object_cells(alpha: np.ndarray, rgb: np.ndarray | None = None, solid: float = SOLID,
                 floor_band: float = FLOOR_BAND, above: float = ABOVE, reach: int = REACH,
                 keep_share: float = KEEP_SHARE, near: int = NEAR) -> np.ndarray:
    """alpha (G, G, G) [ix, iy, iz] one-cell opacity over the box (z up, its floor on the ground), rgb (G, G, G, 3)
    RGB their colour or None -> (G, G, G) bool, the object's cells (all False when nothing is solid). With `rgb`,
    the floor band also keeps the base where it widens (`_widened_base`)."""
    from skimage.measure import label

    cells = alpha > solid
    g = alpha.shape[2]
    band, top = math.ceil(floor_band * g), math.ceil((floor_band + above) * g)
    stands = cells[:, :, band:top].any(axis=2)
    if reach > 0:
        stands = _grow(stands, reach)
    allowed = np.repeat(stands[:, :, None], band, axis=2)
    if rgb is not None and 0 < band < top < g:
        allowed |= _widened_base(cells, rgb, stands, band, top)
    cells[:, :, :band] &= allowed
    pieces = label(cells, connectivity=3)
    sizes = np.bincount(pieces.ravel())[1:]
    if sizes.size == 0:
        return cells
    cells = np.isin(pieces, np.nonzero(sizes >= keep_share * sizes.max())[0] + 1)
    if near > 0:
        cells = _grow(cells, near)
        cells[:, :, :band] &= allowed   # not grown into the ground round the feet
    return cells


def _widened_base(cells: np.ndarray, rgb: np.ndarray, stands: np.ndarray, band: int, top: int) -> np.ndarray:
    """(G, G, band) bool, the floor band's cells beyond `stands` (G, G) that belong to a base wider than what stands
    over the band (the bunny's haunches and paws): from the band's top down, the solid cells within STEP_DOWN cells
    sideways of those kept in the layer above and within FOOTPRINT cells of the footprint of all that is solid above
    the band (a 16x4 fit's teapot, as grey as its ground, flooded it otherwise); of those, the ones whose colour is
    nearer the lower body's (the solid cells of the band's height over `top`) than the ground's (the solid cells of
    the lowest GROUND_LAYERS outside `stands`), by the KNN-th nearest of each in RGB; and the cells next to them in
    their layer that are not solid (so that the object's edge there may grow). None when the ground's own colours
    are told from the body's less often than SEPARATE by the same test (a 16x4 fit's teapot, 0.6 to 0.7). The
    ground's texture and the object's shadow are the ground's colour, and the base of an object whose foot is that
    colour (spot's hooves) stays to the rule without colour."""
    from scipy.spatial import cKDTree

    out = np.zeros(cells.shape[:2] + (band,), bool)
    body = rgb[:, :, top:top + band][cells[:, :, top:top + band]]
    ground = rgb[:, :, :GROUND_LAYERS][cells[:, :, :GROUND_LAYERS] & ~stands[:, :, None]]   # the shadow too
    if len(body) <= KNN or len(ground) <= KNN:
        return out
    body_tree, ground_tree = cKDTree(body), cKDTree(ground)
    told = ground_tree.query(ground, k=KNN + 1)[0][:, -1] < body_tree.query(ground, k=KNN)[0][:, -1]
    if told.mean() < SEPARATE:   # the ground's own colours are not told from the body's
        return out
    wider = np.zeros_like(out)
    under = _grow(cells[:, :, band:].any(axis=2), FOOTPRINT)   # the object's footprint, above the band
    allowed, kept = stands, cells[:, :, band] & stands
    for z in range(band - 1, -1, -1):
        allowed = allowed | (_grow(kept, STEP_DOWN) & under)
        kept = cells[:, :, z] & allowed
        wider[:, :, z] = kept & ~stands
    if not wider.any():
        return out
    colours = rgb[:, :, :band][wider]
    out[wider] = body_tree.query(colours, k=KNN)[0][:, -1] <= ground_tree.query(colours, k=KNN)[0][:, -1]
    beside = np.stack([_grow(out[:, :, z], 1) for z in range(band)], axis=2)
    return out | (beside & ~cells[:, :, :band])


def _grow(mask: np.ndarray, r: int) -> np.ndarray:
    """`mask` dilated by a ball of radius r cells (skimage's isotropic_dilation sets one cell of an empty mask)."""
    from skimage.morphology import isotropic_dilation

    return isotropic_dilation(mask, r) if mask.any() else mask.copy()


def photo_colours(views: np.ndarray, cover: np.ndarray, photos: np.ndarray,
                  ramp: tuple[float, float] = PHOTO_RAMP, solid: np.ndarray | None = None) -> np.ndarray:
    """views (N, H, W, 3) RGB in [0, 1] rendered over white with opacity cover (N, H, W) in [0, 1], photos
    (N, H, W, 3) RGB of the same cameras -> (N, H, W, 3) float32 over white with the same opacity: the colour is the
    photo's where the view is opaque (weight rising from 0 at opacity ramp[0] to 1 at ramp[1]) and the view's own
    (un-premultiplied) colour at its soft edge, where the photo shows the room through the object's outline. With
    `solid` (N, H, W), the cover made solid (`solid_cover`), that colour is laid over white by it instead."""
    a = cover[..., None].astype(np.float32)
    own = np.where(a > 1e-3, (views - (1 - a)) / np.maximum(a, 1e-3), 1.0).clip(0.0, 1.0)
    w = np.clip((a - ramp[0]) / (ramp[1] - ramp[0]), 0.0, 1.0)
    b = a if solid is None else solid[..., None].astype(np.float32)
    return (b * (w * photos + (1 - w) * own) + (1 - b)).astype(np.float32)


def solid_cover(cover: np.ndarray, width: float, subpixel: int = 1) -> np.ndarray:
    """cover: opacity in [0, 1], (N, H, W) views or (N, H, W, 1) (any shape with `subpixel` 1) -> the same shape, made
    solid: from 0 to 1 over `width` about one half, linear between (the half-way outline stays where it is); width 1
    returns cover as it is. With `subpixel` k over 1, each view's cover is resampled k times finer (bilinear, cv2), made
    solid there and averaged back over each pixel's k x k (cv2's INTER_AREA): the outline falls between the pixel
    centres where the cover crosses one half, and a pixel it crosses keeps the share of it that lies inside, as a
    camera's pixel does (an anti-aliased outline, not a step on the pixels)."""
    if width >= 1:
        return cover
    if subpixel <= 1:
        return np.clip((cover - 0.5) / width + 0.5, 0.0, 1.0).astype(cover.dtype)
    import cv2

    views = np.asarray(cover[..., 0] if cover.ndim == 4 else cover, np.float32)
    h, w = views.shape[1:]
    out = np.empty_like(views)
    for i, view in enumerate(views):
        fine = cv2.resize(view, (w * subpixel, h * subpixel), interpolation=cv2.INTER_LINEAR)
        fine = np.clip((fine - 0.5) / width + 0.5, 0.0, 1.0)
        out[i] = cv2.resize(fine, (w, h), interpolation=cv2.INTER_AREA)
    return out.reshape(cover.shape).astype(cover.dtype)


def subpixel_for(setting: int, plane_res: int) -> int:
    """fit --object-subpixel (0: auto) and the planes' resolution -> the grid factor `solid_cover` is given. Auto:
    SUBPIXEL on planes of at most COARSE_RES texels a side, whose coarse field, fitted to a step at the outline,
    spills past it (the chain's 16x4 scenes: 2.03-2.12% of their opacity outside the mask + 2 px with the step,
    1.49-1.74% with the grid 4 times finer), and 1 on finer planes, where the step keeps more of the object in its
    mask (docs/capture-record.md, "The outline made solid on a finer grid")."""
    if setting > 0:
        return setting
    return SUBPIXEL if plane_res <= COARSE_RES else 1


def refined_c2w(c2w: np.ndarray, params: np.ndarray, scale: float) -> np.ndarray:
    """c2w (V, 4, 4) OpenGL of the training views and their `pose_refine` corrections params (V, 6) [axis-angle r |
    shift t in q units] in a box frame of `scale` world units per q unit -> (V, 4, 4) float32, the cameras whose
    rays are the corrected ones (`pose_refine.correct_rays`: origin + t, directions turned by R(r))."""
    import torch

    from .pose_refine import axis_angle_matrix

    rot = axis_angle_matrix(torch.from_numpy(np.asarray(params[:, :3], np.float32))).numpy()
    out = np.array(c2w, np.float32, copy=True)
    out[:, :3, :3] = rot @ out[:, :3, :3]
    out[:, :3, 3] += np.asarray(params[:, 3:], np.float32) * np.float32(scale)
    return out


def object_views(planes, decoder, posed: PosedImages, poses: np.ndarray | None = None, silhouette: float = 1.0,
                 base_keep: float = 0.0, halo: float = 1.0, opaque: float = 1.0, subpixel: int = 1):
    """planes (3, C, R, R) torch, fitted with the background model over posed.box; poses: the fit's pose corrections
    (V, 6) of posed.train, or None -> (the views to fit the object alone to: posed's training views at those poses,
    rendered with the object's cells only over white, at most TEACHER_SIZE pixels on the longer side, their colour
    the photos' where they are opaque (`photo_colours`), as a PosedImages; the object's cells (G, G, G) bool torch,
    their hull), or None when no cell is solid. With `silhouette` under 1, the object's cells that fall outside the
    photos' silhouettes in more than that share of the views (`silhouette.py`) are cut first, in the floor band; and
    with `base_keep` over 0, the floor band's solid cells that its rule drops are kept where they fall outside the
    silhouettes in fewer than that share of the views (a broad base: the bunny's); with `halo` under 1, the cells
    that growing the object's cells added are cut, at every height, where they fall outside the silhouettes not
    grown in more than that share of the views (`halo_vote`); with `opaque` under 1, the views' opacity is made
    solid over that width about one half (`solid_cover`), on a grid `subpixel` times finer than the pixels."""
    import cv2
    import torch

    from .render import cell_alpha, occupancy_from_planes, render_views
    from .sampler import BoxFrame

    box = np.asarray(posed.box, np.float32)
    alpha, rgb = cell_alpha(planes, decoder, box, formats.OCC_RES, with_rgb=True)
    cells = object_cells(alpha, rgb)
    keep = torch.from_numpy(cells).to(planes.device)
    if not bool(keep.any()):
        return None
    frame = BoxFrame.from_box(box, planes.device)
    occ = occupancy_from_planes(planes, decoder, frame)
    tr = posed.train
    c2w = posed.c2w[tr] if poses is None else refined_c2w(posed.c2w[tr], poses, frame.scale)
    scale = min(1.0, TEACHER_SIZE / max(posed.width, posed.height))
    w, h = max(1, round(posed.width * scale)), max(1, round(posed.height * scale))
    intrinsics = (posed.intrinsics[tr] * np.float32(scale)).astype(np.float32)
    views, cover = render_views(planes, decoder, box, c2w, intrinsics, w, h, occ=occ & keep, with_opacity=True)
    photos = posed.images[tr] if (w, h) == (posed.width, posed.height) else \
        np.stack([cv2.resize(p, (w, h), interpolation=cv2.INTER_AREA) for p in posed.images[tr]])
    if silhouette < 1:
        loose = object_cells(alpha, rgb, floor_band=0.0) if base_keep > 0 else None
        core = object_cells(alpha, rgb, near=0) if halo < 1 else None
        cells = _by_silhouettes(cells, loose, core, photos, np.clip(cover, 0.0, 1.0), c2w, intrinsics, box,
                                (silhouette, base_keep, halo))
        keep = torch.from_numpy(cells).to(keep.device)
        views, cover = render_views(planes, decoder, box, c2w, intrinsics, w, h, occ=occ & keep, with_opacity=True)
    cover = np.clip(cover, 0.0, 1.0)
    solid = solid_cover(cover, opaque, subpixel)
    return PosedImages(images=photo_colours(views, cover, photos, solid=solid), alpha=solid, c2w=c2w,
                       intrinsics=intrinsics, box=box, train=np.arange(len(tr)), test=np.arange(0),
                       name=posed.name), keep


def _by_silhouettes(cells, loose, core, photos, cover, c2w, intrinsics, box, shares: tuple) -> np.ndarray:
    """The object's cells (G, G, G) bool after the photos' silhouettes (GrabCut started from the views' opacity
    `cover`), shares = (share, base_keep, halo): over the floor band as they are; in it, those that fall outside the
    silhouettes in at most `share` of the views that see them, and those of `loose` (the cells without the band's
    rule, or None) that fall outside in fewer than `base_keep` of them. The band is where the ground's shadow is
    painted; over it, what the cut misses is the object's own (a grey teapot's spout and handle on a grey ground,
    spot's horns: -3.1 and -1.2 dB when cut at every height). A base that meets the ground along its whole outline
    (the bunny's) stands on no solid cell over the band's top, so the band's rule drops it; the photos hold it in
    nearly every view, where a shadow under a belly falls outside the cut in side views. With `core` (the cells
    before growing, or None) and `halo` under 1, `halo_vote` at every height, against the silhouettes not grown."""
    from snapshot3d.carve import grid_centres

    from .silhouette import grown, outside_share, photo_silhouettes

    share, base_keep, halo = shares
    g = formats.OCC_RES
    band = math.ceil(FLOOR_BAND * g)
    tight = photo_silhouettes(photos, cover, grow=0)
    masks = grown(tight)
    centres = grid_centres(np.asarray(box, np.float64), g)
    out = band_vote(cells, loose, outside_share(centres[:, :, :band].reshape(-1, 3), c2w, intrinsics,
                                                masks).reshape(g, g, band), share, base_keep)
    if core is None or halo >= 1:
        return out
    return halo_vote(out, core, outside_share(centres.reshape(-1, 3), c2w, intrinsics, tight).reshape(g, g, g), halo)


def halo_vote(cells: np.ndarray, core: np.ndarray, outside: np.ndarray, share: float) -> np.ndarray:
    """cells (G, G, G) bool, the object's (grown), core (G, G, G) bool the same before growing, outside (G, G, G) the
    share of the views that see each cell in which it falls outside the photos' silhouettes (not grown) -> (G, G, G)
    bool: the core's cells as they are, the cells growing added where they are outside in at most `share` of their
    views. Growing keeps thin parts that are not solid (a spout, a knob), which the photos show, and the haze the
    fit paints round the outline, which they do not; on spot's and the teapot's arcs the vote also cut the object's
    outer skin (-1.5 and -2.2 dB, docs/capture-record.md, "The edge that is too wide"), so fit --object-halo is off."""
    return cells & (core | (outside <= share))


def band_vote(cells: np.ndarray, loose: np.ndarray | None, outside: np.ndarray, share: float,
              base_keep: float) -> np.ndarray:
    """cells, loose (G, G, G) bool (loose: the cells without the floor band's rule, or None) and outside (G, G, B)
    the share of the views that see each of the lowest B cells (the floor band) in which it falls outside the
    photos' silhouettes -> (G, G, G) bool: `cells` over the band; in it, those outside in at most `share` of their
    views, and those of `loose` alone outside in fewer than `base_keep`."""
    band = outside.shape[2]
    out = cells.copy()
    out[:, :, :band] &= outside <= share
    if loose is not None:
        out[:, :, :band] |= loose[:, :, :band] & ~cells[:, :, :band] & (outside < base_keep)
    return out


def object_config(cfg):
    """The FitConfig of the fit to `object_views`: round(cfg.steps * cfg.object_steps) steps, each ray over a
    random colour (its target recomposited by the views' opacity), from DISTIL_LR down to cfg's last learning rate,
    the poses as they are; its last cfg.object_channel of steps through the print channel's noise (0 or auto left
    unresolved: cfg.channel_fraction's)."""
    steps = max(1, round(cfg.steps * cfg.object_steps))
    return replace(cfg, steps=steps, background="white", refine_poses="off", object_steps=0.0, random_background=True,
                   channel_fraction=cfg.object_channel if cfg.object_channel > 0 else cfg.channel_fraction, lr=DISTIL_LR,
                   lr_final=min(cfg.lr_final, DISTIL_LR), occ_warmup=max(1, steps // 10))
