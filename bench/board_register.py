"""Printed ArUco boards for `bench channel --real` (issue 38 item 5): their exact digital templates
(`cv2.aruco.CharucoBoard` / `GridBoard`, `generateImage`), a sheet-sized canvas that carries one through the
simulator, and the registration of a photo onto a template.

Quads: every black square the ArUco detector outlines (decoded markers and rejected candidates alike: OpenCV 5
decodes none of the opencv_contrib tutorial PNGs' markers with any predefined dictionary, flipped or inverted,
so the bits are not used), corners refined with `cornerSubPix`; quads without a dark border on a lighter
surround, nested and isolated ones are dropped. Registration: the quads' centres are matched to the template's
cells (the hull's four corner quads in each cyclic order give a first homography), then one homography from all
matched quad corners (RANSAC, then least squares on the quads whose corners all lie within 3 px).

Images: photos are BGR uint8 (H, W, 3) as cv2.imread gives; board coordinates are board units (one chessboard
square, or one grid marker), x right, y down, origin at the board's top-left."""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from snapshot3d.errors import UserError

__all__ = ["BoardSpec", "KNOWN_BOARDS", "BOARD_FILL", "board_quads", "board_template", "sheet_canvas", "snap_per_unit",
           "find_quads", "register_board"]

BOARD_FILL = 0.9                 # the board's height (with its margin) / the sheet's height on the canvas
_MARGIN = 0.5                    # white margin around the board in the template, board units
_DETECT_SIDE = 1600              # quads are found on a copy of at most this many pixels on its long side

@dataclass(frozen=True)
class BoardSpec:
    """A printed board: `kind` "charuco" (cols x rows chessboard squares of 1 unit, markers of side `ratio` in
    the white ones) or "grid" (cols x rows markers of 1 unit, gaps of `ratio`); DICT_6X6_250 draws the
    template (the bits are not used to register or measure)."""

    kind: str
    cols: int
    rows: int
    ratio: float
    dictionary: str = "DICT_6X6_250"

    def board(self):
        d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))
        if self.kind == "charuco":
            return cv2.aruco.CharucoBoard((self.cols, self.rows), 1.0, self.ratio, d)
        return cv2.aruco.GridBoard((self.cols, self.rows), 1.0, self.ratio, d)

    def extent(self) -> tuple[float, float]:
        """(width, height) of the board without margin, board units."""
        if self.kind == "charuco":
            return float(self.cols), float(self.rows)
        return self.cols + (self.cols - 1) * self.ratio, self.rows + (self.rows - 1) * self.ratio


KNOWN_BOARDS = {
    "charuco": [BoardSpec("charuco", 5, 7, r) for r in (0.5, 0.55, 0.6, 0.65, 0.7, 0.75, 0.8)],
    "grid": [BoardSpec("grid", 5, 7, r) for r in (0.1, 0.15, 0.2, 0.25, 0.3, 0.4, 0.5)],
}
"""the boards of opencv_contrib's aruco tutorials (5 x 7 ChArUco, 5 x 7 grid), with the candidate ratios tried"""


def board_quads(spec: BoardSpec) -> tuple[np.ndarray, np.ndarray]:
    """The board's black quads: (Q, 4, 2) float64 corners in board units (clockwise from top-left) and (Q,)
    bool, True for a whole black square (a ChArUco chessboard square; markers False)."""
    quads, full = [], []
    if spec.kind == "charuco":
        m = spec.ratio
        for r in range(spec.rows):
            for c in range(spec.cols):
                if (c + r) % 2 == 0:
                    x0, y0, s = c, r, 1.0
                else:
                    x0, y0, s = c + (1 - m) / 2, r + (1 - m) / 2, m
                quads.append([[x0, y0], [x0 + s, y0], [x0 + s, y0 + s], [x0, y0 + s]])
                full.append((c + r) % 2 == 0)
    else:
        p = 1.0 + spec.ratio
        for r in range(spec.rows):
            for c in range(spec.cols):
                x0, y0 = c * p, r * p
                quads.append([[x0, y0], [x0 + 1, y0], [x0 + 1, y0 + 1], [x0, y0 + 1]])
                full.append(False)
    return np.array(quads, np.float64), np.array(full)


def board_template(spec: BoardSpec, px_per_unit: int) -> np.ndarray:
    """The board's exact digital template (`generateImage`), (H, W) uint8 grey, with a white margin of
    `_MARGIN` units: board point (u, v) lies at pixel ((u + _MARGIN) * px_per_unit - 0.5, ...)."""
    w, h = spec.extent()
    m = int(round(_MARGIN * px_per_unit))
    size = (int(round(w * px_per_unit)) + 2 * m, int(round(h * px_per_unit)) + 2 * m)
    return spec.board().generateImage(size, marginSize=m, borderBits=1)


def sheet_canvas(spec: BoardSpec, px_per_unit: float = 2.0) -> tuple[np.ndarray, float]:
    """A sheet-sized canvas (`layout.sheet_size()` at `px_per_unit` pixels per layout unit, (H, W, 3) uint8 RGB,
    white) with the board's template centred on it, its height `BOARD_FILL` of the sheet's. Returns the
    canvas and the snapshot pixels per board unit."""
    from snapshot3d.scanner import layout

    sw, sh = layout.sheet_size()
    W, H = int(round(sw * px_per_unit)), int(round(sh * px_per_unit))
    bw, bh = spec.extent()
    tpl_ppu = int(BOARD_FILL * H / (bh + 2 * _MARGIN))
    tpl = board_template(spec, tpl_ppu)
    canvas = np.full((H, W, 3), 255, np.uint8)
    y0, x0 = (H - tpl.shape[0]) // 2, (W - tpl.shape[1]) // 2
    canvas[y0:y0 + tpl.shape[0], x0:x0 + tpl.shape[1]] = tpl[..., None]
    return canvas, tpl_ppu / px_per_unit


def snap_per_unit(spec: BoardSpec) -> float:
    """Snapshot pixels per board unit when the board fills a sheet as in `sheet_canvas`."""
    from snapshot3d.scanner import layout

    sh = layout.sheet_size()[1]
    H = int(round(sh * 2.0))
    return int(BOARD_FILL * H / (spec.extent()[1] + 2 * _MARGIN)) / 2.0


# --- finding and registering the quads ---

def _poly_area(q: np.ndarray) -> float:
    x, y = q[:, 0], q[:, 1]
    return 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))


def _dark_border(grey: np.ndarray, q: np.ndarray) -> bool:
    """A quad with a dark band just inside its outline and a lighter one just outside (a black square or marker
    on white), not e.g. the outline of the white sheet itself."""
    c = q.mean(0)
    f = np.linspace(0.15, 0.85, 9)
    pts = np.concatenate([q[k] + np.outer(f, q[(k + 1) % 4] - q[k]) for k in range(4)])
    inner = c + (pts - c) * 0.93
    outer = c + (pts - c) * 1.07
    h, w = grey.shape

    def at(p):
        x = np.clip(np.round(p[:, 0]).astype(int), 0, w - 1)
        y = np.clip(np.round(p[:, 1]).astype(int), 0, h - 1)
        return grey[y, x].astype(np.float64)
    return float(np.median(at(outer)) - np.median(at(inner))) > 30.0


def find_quads(img: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(Q, 4, 2) float64 photo-pixel corners of the black quads the ArUco detector outlines in a BGR photo
    (decoded or not), refined to sub-pixel, and (Q,) bool: decoded as a DICT_6X6_250 marker. Quads inside
    another, tiny ones, and ones far from every other quad are dropped. UserError when fewer than 4 are
    found."""
    grey = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY) if img.ndim == 3 else img
    f = min(1.0, _DETECT_SIDE / max(grey.shape))
    small = grey if f == 1.0 else cv2.resize(grey, None, fx=f, fy=f, interpolation=cv2.INTER_AREA)
    det = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_6X6_250),
                                  cv2.aruco.DetectorParameters())
    corners, _ids, rejected = det.detectMarkers(small)
    cands = [(np.asarray(c, np.float64).reshape(4, 2) / f, i < len(corners))
             for i, c in enumerate(list(corners) + list(rejected))]
    cands = [c for c in cands if _poly_area(c[0]) > 64.0 and _dark_border(grey, c[0])]
    if len(cands) < 4:
        raise UserError(f"no ArUco board found: {len(cands)} black square(s) outlined in the photo, 4 needed")
    q = np.array([c[0] for c in cands])
    dec = np.array([c[1] for c in cands])
    area = np.array([_poly_area(x) for x in q])
    keep = np.ones(len(q), bool)
    cen = q.mean(1)
    for i in np.argsort(-area):              # drop quads nested in a larger kept one (bits, inner contours)
        if not keep[i]:
            continue
        for j in np.nonzero(keep)[0]:
            if j != i and area[j] < area[i] and cv2.pointPolygonTest(q[i].astype(np.float32),
                                                                     tuple(map(float, cen[j])), False) >= 0:
                keep[j] = False
    q, dec, cen, area = q[keep], dec[keep], cen[keep], area[keep]
    side = np.sqrt(area)
    # the largest group of quads within 6 sides of each other (drops stray quads in the background)
    d = np.linalg.norm(cen[:, None] - cen[None], axis=2)
    adj = d < 6 * np.maximum(side[:, None], side[None])
    label = -np.ones(len(q), int)
    for s in range(len(q)):
        if label[s] >= 0:
            continue
        stack, label[s] = [s], s
        while stack:
            k = stack.pop()
            for j in np.nonzero(adj[k] & (label < 0))[0]:
                label[j] = s
                stack.append(j)
    big = np.bincount(label).argmax()
    q, dec = q[label == big], dec[label == big]
    if len(q) < 4:
        raise UserError(f"no ArUco board found: only {len(q)} black squares lie together in the photo, 4 needed")
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.01)
    out = []
    for x in q:
        s = np.sqrt(_poly_area(x))
        win = int(np.clip(s / 12, 2, 12))
        pts = np.ascontiguousarray(x, np.float32).reshape(-1, 1, 2)
        cv2.cornerSubPix(grey, pts, (win, win), (-1, -1), crit)
        out.append(pts.reshape(4, 2).astype(np.float64))
    return np.array(out), dec


def _clockwise(pts: np.ndarray) -> np.ndarray:
    c = pts.mean(0)
    return pts[np.argsort(np.arctan2(pts[:, 1] - c[1], pts[:, 0] - c[0]))]


def _hull4(cen: np.ndarray) -> np.ndarray | None:
    hull = cv2.convexHull(cen.astype(np.float32)).reshape(-1, 2)
    peri = cv2.arcLength(hull.reshape(-1, 1, 2), True)
    for eps in np.linspace(0.01, 0.2, 20):
        ap = cv2.approxPolyDP(hull.reshape(-1, 1, 2), eps * peri, True).reshape(-1, 2)
        if len(ap) == 4:
            return _clockwise(ap.astype(np.float64))
        if len(ap) < 4:
            return None
    return None


def _fit(spec: BoardSpec, quads: np.ndarray):
    """Match photo quads to the template's (hypotheses: the hull's 4 corners in each cyclic order); returns
    (matched count, rms px, H board->photo, [(photo quad idx, template quad idx, corner order)]) or None."""
    tq, _ = board_quads(spec)
    tcen = tq.mean(1)
    cen = quads.mean(1)
    side = np.sqrt([_poly_area(x) for x in quads])
    hull = _hull4(cen)
    if hull is None:
        return None
    n_r, n_c = spec.rows, spec.cols
    corner_cells = [0, n_c - 1, n_r * n_c - 1, (n_r - 1) * n_c]
    best = None
    for shift in range(4):
        src = tcen[corner_cells]
        dst = np.roll(hull, -shift, axis=0)
        H = cv2.getPerspectiveTransform(src.astype(np.float32), dst.astype(np.float32)).astype(np.float64)
        pairs = []
        for _ in range(3):
            proj = cv2.perspectiveTransform(tcen.reshape(-1, 1, 2), H).reshape(-1, 2)
            d = np.linalg.norm(proj[:, None] - cen[None], axis=2)
            pairs = []
            for t in range(len(tcen)):
                p = int(d[t].argmin())
                if d[t, p] < 0.4 * side[p] and int(d[:, p].argmin()) == t:
                    pairs.append((p, t))
            if len(pairs) < 4:
                break
            H, _ = cv2.findHomography(tcen[[t for _, t in pairs]], cen[[p for p, _ in pairs]], 0)
            if H is None:
                break
        if len(pairs) < 4 or H is None:
            continue
        # corners: each photo quad's corners in the order of its template quad's, by nearest after H
        src_pts, dst_pts, matched = [], [], []
        for p, t in pairs:
            proj = cv2.perspectiveTransform(tq[t].reshape(-1, 1, 2), H).reshape(4, 2)
            order = np.linalg.norm(proj[:, None] - quads[p][None], axis=2).argmin(1)
            if len(set(order.tolist())) < 4:
                continue
            src_pts.append(tq[t])
            dst_pts.append(quads[p][order])
            matched.append((p, t, order))
        if len(matched) < 4:
            continue
        s, dd = np.concatenate(src_pts), np.concatenate(dst_pts)
        H, _ = cv2.findHomography(s, dd, cv2.RANSAC, 2.0)
        if H is None:
            continue
        err = np.linalg.norm(cv2.perspectiveTransform(s.reshape(-1, 1, 2), H).reshape(-1, 2) - dd, axis=1)
        good = err.reshape(-1, 4).max(1) < 3.0         # a quad whose outline is off is not used
        matched = [m for m, g in zip(matched, good) if g]
        if len(matched) < 4:
            continue
        ok = np.repeat(good, 4)
        H, _ = cv2.findHomography(s[ok], dd[ok], 0)
        rms = float(np.sqrt(np.mean(np.sum((cv2.perspectiveTransform(s[ok].reshape(-1, 1, 2), H).reshape(-1, 2)
                                            - dd[ok]) ** 2, 1))))
        cand = (len(matched), -rms, H, matched)
        if best is None or cand[:2] > best[:2]:
            best = cand
    if best is None:
        return None
    return best[0], -best[1], best[2], best[3]


def register_board(quads: np.ndarray, specs: list[BoardSpec]) -> dict | None:
    """The best fit of the photo's quads to one of `specs` (most quads matched, then lowest RMS reprojection
    error of their corners; a quad with a corner 3 px off the fit is left out); None when none matches 70 % of
    its quads. Returns {spec, H (3, 3) board units ->
    photo px, rms_px, matched: [(photo quad, template quad, corner order)]}."""
    best = None
    for spec in specs:
        r = _fit(spec, quads)
        if r is None or r[0] < 0.7 * spec.rows * spec.cols:
            continue
        if best is None or (r[0], -r[1]) > (best[0], -best[1]):
            best = (*r, spec)
    if best is None:
        return None
    n, rms, H, matched, spec = best
    return {"spec": spec, "H": H, "rms_px": rms, "matched": matched}
