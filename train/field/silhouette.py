"""The object's silhouette in each training photo, and the cells of the box that fall outside it in too many of them
(fit --object-silhouette; object_carve.object_views). A fit with the background model paints a skirt of the
ground's colour under the object (the ground's soft shadow, finer than the background model's cells there): it is
seen by as many views as the object's surface and is as solid, so the rules on the planes' own cells keep it. In a
side view it fills the gap between the legs, where the photo shows the ground. So each photo is cut by OpenCV's
GrabCut, started from the planes' own opacity in that view (opaque: probably the object; near it: probably not;
farther: not), and a cell that projects outside the cut, grown by a few pixels, in more than a share of the views
where it lies in the image is not the object's (the visual hull's rule, with votes, since a photo's cut can miss a
dark hoof that looks like the shadow next to it)."""
from __future__ import annotations

import numpy as np

__all__ = ["photo_silhouettes", "outside_share", "seen_past", "GROW", "BAND", "ITERATIONS", "OPAQUE", "TOUCHED", "SEEN", "FAILED"]

GROW = 0.015       # of the view's longer side: the cut is grown by this before the cells are judged (2 px at 128;
#                    3 px kept the contact shadow's ring round a duck's or a teapot's base, 1 px cut spot's hooves)
BAND = 0.035       # of the longer side: round the planes' opacity, what GrabCut may give to either side (4 px at 128)
ITERATIONS = 5     # GrabCut's
OPAQUE = 0.5       # the planes' opacity from which a pixel is probably the object's
TOUCHED = 0.02     # ... and under which, farther than BAND from it, it is the background's for certain
SEEN = 0.5         # a view votes on a cell when at least this much of the light from it passes the object
FAILED = 0.5       # a cut that keeps less than this share of the opaque pixels failed (the photo does not show what
#                    the planes do: a grey teapot's view, 0.22; the others 0.91 to 1), and its view does not vote


def photo_silhouettes(photos: np.ndarray, cover: np.ndarray) -> list:
    """photos (N, H, W, 3) RGB in [0, 1], cover (N, H, W) the planes' opacity in the same views -> N masks (H, W) bool
    of the object as GrabCut cuts each photo, grown by GROW of the longer side; None for a view that holds no
    opaque pixel or no background to learn from, or whose cut keeps less than FAILED of its opaque pixels."""
    import cv2

    h, w = cover.shape[1:]
    longer = max(h, w)
    grow, band = max(1, round(GROW * longer)), max(1, round(BAND * longer))
    near_kernel, grow_kernel = np.ones((2 * band + 1,) * 2, np.uint8), np.ones((2 * grow + 1,) * 2, np.uint8)
    out = []
    for photo, acc in zip(photos, cover):
        init = np.full(acc.shape, cv2.GC_BGD, np.uint8)
        init[cv2.dilate((acc > TOUCHED).astype(np.uint8), near_kernel) > 0] = cv2.GC_PR_BGD
        init[acc > OPAQUE] = cv2.GC_PR_FGD
        if not (init == cv2.GC_PR_FGD).any() or not (init == cv2.GC_BGD).any():
            out.append(None)
            continue
        bgr = np.ascontiguousarray((np.clip(photo, 0, 1) * 255 + 0.5).astype(np.uint8)[..., ::-1])
        cv2.setRNGSeed(0)   # GrabCut's k-means draws from OpenCV's global generator: the same cut whatever ran before
        cv2.grabCut(bgr, init, None, np.zeros((1, 65)), np.zeros((1, 65)), ITERATIONS, cv2.GC_INIT_WITH_MASK)
        opaque = acc > OPAQUE
        cut = (init == cv2.GC_FGD) | (init == cv2.GC_PR_FGD)
        out.append(cv2.dilate(cut.astype(np.uint8), grow_kernel) > 0 if cut[opaque].mean() >= FAILED else None)
    return out


def outside_share(points: np.ndarray, c2w: np.ndarray, intrinsics: np.ndarray, masks: list,
                  visible: np.ndarray | None = None) -> np.ndarray:
    """points (M, 3) world, cameras c2w (N, 4, 4) OpenGL with intrinsics (N, 4) (pixel centres at +0.5), masks: N
    (H, W) bool or None, visible: (N, M) bool, the views that see each point (`seen_past`), or None (all) -> (M,) the
    share of the views with a mask, among those that see a point and in whose image it lies, in which it falls
    outside the mask (0 where there is no such view)."""
    from snapshot3d.bundle import projection

    hom = np.c_[points, np.ones(len(points))]
    outside, seen = np.zeros(len(points)), np.zeros(len(points))
    for i, (pose, intr, mask) in enumerate(zip(c2w, intrinsics, masks)):
        if mask is None:
            continue
        x = hom @ projection(pose, intr).T
        front = x[:, 2] > 1e-9
        z = np.where(front, x[:, 2], 1.0)
        u, v = np.floor(x[:, 0] / z), np.floor(x[:, 1] / z)
        ok = front & (u >= 0) & (v >= 0) & (u < mask.shape[1]) & (v < mask.shape[0])
        if visible is not None:
            ok &= visible[i]
        seen += ok
        outside[ok] += ~mask[v[ok].astype(int), u[ok].astype(int)]
    return outside / np.maximum(seen, 1)


def seen_past(points: np.ndarray, c2w: np.ndarray, alpha: np.ndarray, box: np.ndarray,
              min_transmittance: float = SEEN) -> np.ndarray:
    """points (M, 3) world, cameras c2w (N, 4, 4) OpenGL, alpha (G, G, G) [ix, iy, iz] the one-cell opacity of what
    may hide a point (the object's cells above the floor band) over world `box` (2, 3) -> (N, M) bool: the views in
    which the light from each point passes those cells with at least `min_transmittance` left. A view in which a
    cell lies behind the object shows the object there whether or not the cell is solid: it says nothing of it (a
    frontal arc of views sees the ground behind the feet only from the arc's ends)."""
    box = np.asarray(box, np.float64)
    g = alpha.shape[0]
    cell = (box[1] - box[0]) / g
    depth = -np.log(np.clip(1.0 - alpha, 1e-6, 1.0))   # optical depth of one cell's length
    out = np.zeros((len(c2w), len(points)), bool)
    for i, pose in enumerate(c2w):
        cam = pose[:3, 3]
        seg = points - cam                                   # (M, 3): from the camera to each point
        with np.errstate(divide="ignore", invalid="ignore"):
            t0 = np.where(seg != 0, (box[0] - cam) / seg, -np.inf)
            t1 = np.where(seg != 0, (box[1] - cam) / seg, np.inf)
        enter = np.clip(np.max(np.minimum(t0, t1), axis=1), 0.0, 1.0)   # where the segment enters the box
        length = np.linalg.norm(seg / cell, axis=1)                       # the segment's length in cells
        stop = 1.0 - 1.0 / np.maximum(length, 1.0)                        # a cell short of the point itself
        n = int(np.ceil(2 * length.max() * (1 - enter.min()))) + 1        # half a cell apart
        t = enter[:, None] + (stop - enter)[:, None] * (np.arange(n) + 0.5)[None] / n
        idx = np.floor((cam + t[..., None] * seg[:, None] - box[0]) / cell).astype(int)
        inside = np.all((idx >= 0) & (idx < g), axis=-1) & (stop > enter)[:, None]
        idx = np.clip(idx, 0, g - 1)
        step = np.maximum(stop - enter, 0.0) * length / n                 # each sample's share, in cells
        tau = (depth[idx[..., 0], idx[..., 1], idx[..., 2]] * inside).sum(axis=1) * step
        out[i] = np.exp(-tau) >= min_transmittance
    return out
