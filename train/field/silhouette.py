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

__all__ = ["photo_silhouettes", "grown", "outside_share", "GROW", "BAND", "ITERATIONS", "OPAQUE", "TOUCHED", "FAILED"]

GROW = 0.015       # of the view's longer side: the cut is grown by this before the cells are judged (2 px at 128;
#                    3 px kept the contact shadow's ring round a duck's or a teapot's base, 1 px cut spot's hooves)
BAND = 0.035       # of the longer side: round the planes' opacity, what GrabCut may give to either side (4 px at 128)
ITERATIONS = 5     # GrabCut's
OPAQUE = 0.5       # the planes' opacity from which a pixel is probably the object's
TOUCHED = 0.02     # ... and under which, farther than BAND from it, it is the background's for certain
FAILED = 0.5       # a cut that keeps less than this share of the opaque pixels failed (the photo does not show what
#                    the planes do: a grey teapot's view, 0.22; the others 0.91 to 1), and its view does not vote


def photo_silhouettes(photos: np.ndarray, cover: np.ndarray, grow: int | None = None) -> list:
    """photos (N, H, W, 3) RGB in [0, 1], cover (N, H, W) the planes' opacity in the same views -> N masks (H, W) bool
    of the object as GrabCut cuts each photo, grown by `grow` pixels (None: GROW of the longer side, at least 1);
    None for a view that holds no opaque pixel or no background to learn from, or whose cut keeps less than FAILED
    of its opaque pixels."""
    import cv2

    h, w = cover.shape[1:]
    band = max(1, round(BAND * max(h, w)))
    near_kernel = np.ones((2 * band + 1,) * 2, np.uint8)
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
        out.append(cut if cut[opaque].mean() >= FAILED else None)
    return grown(out, grow)


def grown(masks: list, grow: int | None = None) -> list:
    """masks: (H, W) bool or None each -> the same dilated by `grow` pixels (None: GROW of the longer side, at least
    1; 0: as they are); None stays None."""
    import cv2

    shape = next((m.shape for m in masks if m is not None), None)
    if shape is None:
        return list(masks)
    grow = max(1, round(GROW * max(shape))) if grow is None else grow
    if grow <= 0:
        return list(masks)
    kernel = np.ones((2 * grow + 1,) * 2, np.uint8)
    return [None if m is None else cv2.dilate(m.astype(np.uint8), kernel) > 0 for m in masks]


def outside_share(points: np.ndarray, c2w: np.ndarray, intrinsics: np.ndarray, masks: list) -> np.ndarray:
    """points (M, 3) world, cameras c2w (N, 4, 4) OpenGL with intrinsics (N, 4) (pixel centres at +0.5), masks: N
    (H, W) bool or None -> (M,) the share of the views with a mask, among those in whose image a point lies, in which
    it falls outside the mask (0 where it lies in no such image)."""
    from snapshot3d.bundle import projection

    hom = np.c_[points, np.ones(len(points))]
    outside, seen = np.zeros(len(points)), np.zeros(len(points))
    for pose, intr, mask in zip(c2w, intrinsics, masks):
        if mask is None:
            continue
        x = hom @ projection(pose, intr).T
        front = x[:, 2] > 1e-9
        z = np.where(front, x[:, 2], 1.0)
        u, v = np.floor(x[:, 0] / z), np.floor(x[:, 1] / z)
        ok = front & (u >= 0) & (v >= 0) & (u < mask.shape[1]) & (v < mask.shape[0])
        seen += ok
        outside[ok] += ~mask[v[ok].astype(int), u[ok].astype(int)]
    return outside / np.maximum(seen, 1)
