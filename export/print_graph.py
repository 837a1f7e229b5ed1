"""The print medium's restore graph in torch, for export to ONNX (`restore-print.onnx`): the designed
receiver of `snapshot3d.codecs.print_read` (`read_carriers` with the bands combined, then `restore_layout`)
step for step, in float32, with the layout as inputs (`snapshot3d.codecs.print_feeds`), so that one graph reads
every plane size and both print codecs. The numpy code stays the reference; `export.parity.print_parity`
holds the graph to it on real captures.

Inputs: snapshot (1, 3, 380, 380) float32 RGB in [0, 1], then `print_feeds.LAYOUT_INPUTS`. Outputs:
planes (3, C, R, R) float32 (not clipped or rounded), reading (3,) float32 (gain, noise, plane_rmse)."""
from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from snapshot3d import formats
from snapshot3d.codecs import print_carriers, print_fold, print_read

__all__ = ["PrintRestoreGraph"]

_BANDS = tuple(print_carriers.PRINT_BANDS)   # the pool's order: Y2LH, Y2HL, Y2HH, Y1LH, Y1HL, RG2LH, RG2HL


def haar(x: Tensor):
    a, b, c, d = x[..., 0::2, 0::2], x[..., 0::2, 1::2], x[..., 1::2, 0::2], x[..., 1::2, 1::2]
    return (a + b + c + d) / 2, (a - b + c - d) / 2, (a + b - c - d) / 2, (a - b - c + d) / 2


def _pool(img: Tensor) -> Tensor:
    """img (3, H, W) RGB -> the flat pool of the codec's bands (`bands.analyse`, `print_carriers.flat`)."""
    y = img.sum(0) / math.sqrt(3.0)
    rg = (img[0] - img[1]) / math.sqrt(2.0)
    yll, ylh1, yhl1, _ = haar(y)
    _, ylh2, yhl2, yhh2 = haar(yll)
    _, rlh2, rhl2, _ = haar(haar(rg)[0])
    got = {"Y2LH": ylh2, "Y2HL": yhl2, "Y2HH": yhh2, "Y1LH": ylh1, "Y1HL": yhl1, "RG2LH": rlh2, "RG2HL": rhl2}
    return torch.cat([got[b].reshape(-1) for b in _BANDS])


def _noise_pool(img: Tensor) -> Tensor:
    """img (3, H, W) -> `print_carriers.noise_map`: the print's noise power at every coefficient of the pool."""
    sigma, half = 2.0, 8    # cv2.GaussianBlur(sigma=2) on float32: 17 taps, border reflect-101
    t = torch.arange(-half, half + 1, dtype=torch.float32)
    k = torch.exp(-t * t / (2 * sigma * sigma))
    k = k / k.sum()
    grey = F.pad(img.mean(0)[None, None], (half, half, half, half), mode="reflect")
    grey = F.conv2d(F.conv2d(grey, k.view(1, 1, 1, -1)), k.view(1, 1, -1, 1))
    maps = {1: F.avg_pool2d(grey, 2)[0, 0], 2: F.avg_pool2d(grey, 4)[0, 0]}
    noise = {}
    for lvl, m in maps.items():
        s = m.clamp(0.0, 1.0)
        dlin = torch.where(s <= 0.04045, torch.full_like(s, 1 / 12.92), 2.4 / 1.055 * ((s + 0.055) / 1.055) ** 1.4)
        noise[lvl] = print_carriers.PRINT_NOISE * torch.clamp(1.0 / (dlin * dlin), max=100.0)
    return torch.cat([noise[int(b[-3])].reshape(-1) for b in _BANDS])


def _band_edges() -> list[int]:
    n = formats.SNAPSHOT_SIZE
    sizes = [(n // 2 if b[-3] == "1" else n // 4) ** 2 for b in _BANDS]
    return [sum(sizes[:i + 1]) for i in range(len(sizes) - 1)]


def _solve(a: Tensor, b: Tensor) -> Tensor:
    """a (n, n) symmetric positive definite, b (n,) -> a^-1 b: Gauss-Jordan without pivoting, unrolled (n is
    the fixed number of bands)."""
    n = a.shape[0]
    m = torch.cat([a, b[:, None]], 1)
    for j in range(n):
        piv = m[j] / m[j, j]
        m = m - m[:, j:j + 1] * piv[None, :]
        m = torch.cat([m[:j], piv[None], m[j + 1:]], 0)
    return m[:, n]


def _pilot_snr(vals: Tensor, f: Tensor, signs: Tensor) -> Tensor:
    """The pilots' SNR through filters f, normalised first: a degenerate combination's filters reach 1e20 and more,
    whose squares overflow float32 (inf / inf would compare as true in onnxruntime)."""
    x = (vals * f).sum(1) * signs
    x = x / torch.clamp(x.abs().max(), min=1e-30)
    mean = x.mean()
    return mean * mean / torch.clamp(((x - mean) ** 2).mean(), min=1e-30)


def _posterior(g: Tensor, y_lin, a_lin, n_lin, y_cos, y_sin, amp, n_cos, n_sin):
    """`print_fold._posterior`: g (F, G) grid of x -> the posterior mean and variance of x (F,)."""
    turns = print_fold.FOLD_TURNS
    col = (lambda v: v[:, None])
    ll = (-(col(y_lin) - col(a_lin) * g) ** 2 / (2 * col(n_lin))
          - (col(y_cos) - col(amp) * torch.cos(turns * g)) ** 2 / (2 * col(n_cos))
          - (col(y_sin) - col(amp) * torch.sin(turns * g)) ** 2 / (2 * col(n_sin)) - g * g / 2)
    w = torch.softmax(ll, dim=1)
    mean = (w * g).sum(1)
    return mean, torch.clamp((w * g * g).sum(1) - mean * mean, min=0.0)


class PrintRestoreGraph(nn.Module):
    def __init__(self):
        super().__init__()
        self.register_buffer("grid", torch.tensor(print_fold._GRID, dtype=torch.float32))
        self.register_buffer("fine", torch.tensor(print_fold._FINE, dtype=torch.float32))
        self.edges = _band_edges()

    def _filters(self, vals: Tensor, noise: Tensor, base: Tensor, chips: Tensor, pilots: Tensor) -> Tensor:
        """`print_carriers.filters`, then `band_weights`: the filters (N, K) that read each carrier."""
        w = base / torch.sqrt(noise)
        w = w / torch.sqrt((w * w).sum(1, keepdim=True))
        q = w / noise
        q = q / (q * w).sum(1, keepdim=True)
        p = print_carriers.PILOTS
        band = sum((chips >= e).to(torch.int64) for e in self.edges)                     # (N, K)
        onehot = (band[..., None] == torch.arange(len(_BANDS))).to(torch.float32)        # (N, K, nb)
        signs = pilots / pilots.abs().mean()
        shape = torch.einsum("nk,nkb->nb", q[:p] * w[:p], onehot[:p]) * pilots[:, None]
        read = torch.einsum("nk,nkb->nb", q[:p] * vals[:p], onehot[:p])
        gain = (read * shape).sum(0) / torch.clamp((shape * shape).sum(0), min=1e-30)
        resid = read - gain * shape
        cov = resid.t() @ resid / p
        nb = len(_BANDS)
        cov = cov + torch.eye(nb) * (1e-3 * torch.diagonal(cov).sum() / nb)
        beta = _solve(cov, gain * shape.abs().mean(0))
        share = torch.einsum("nk,nkb->nb", q * w, onehot)
        resp = share @ (beta * gain)
        ok = resp > 1e-3 * resp.abs().mean()
        keep = (share @ gain) / torch.where(ok, resp, torch.ones_like(resp))
        combined = torch.where(ok[:, None], q * beta[band] * keep[:, None], q)
        positive = 2 * (resp > 0).to(torch.int64).sum() > resp.shape[0]
        better = _pilot_snr(vals[:p], combined[:p], signs) > _pilot_snr(vals[:p], q[:p], signs)
        return torch.where(positive & better, combined, q)

    def forward(self, snapshot: Tensor, chips: Tensor, base: Tensor, place: Tensor, scale: Tensor, prior: Tensor,
                pilots: Tensor, folded: Tensor, fold_amp: Tensor, dct: Tensor, prior_rest: Tensor):
        img = snapshot[0]
        vals, noise = _pool(img)[chips], _noise_pool(img)[chips]
        f = self._filters(vals, noise, base, chips, pilots)
        read, factor = (vals * f).sum(1), (f * f * noise).sum(1)
        # restore_layout (strength 1)
        p, m, nf = print_carriers.PILOTS, scale.shape[0], folded.shape[0]
        amp = pilots.abs().mean()
        pil = read[:p] * pilots / amp
        gain = torch.clamp(pil.mean() / amp, min=1e-3)
        unit = torch.clamp(((pil - gain * amp) ** 2 / factor[:p]).mean(), min=1e-14)
        nse = unit * factor[p:]
        a, y, n = scale * gain, read[p:], nse[:m]
        w = print_read.linear_weight(a * a, prior, n)
        est = w / a * y[:m]
        err = print_read.linear_error(w, prior)
        sd = torch.sqrt(prior[folded])
        args = (y[folded], a[folded] * sd, n[folded], y[m:m + nf], y[m + nf:], gain * fold_amp,
                nse[m:m + nf], nse[m + nf:])
        mean, var = _posterior(self.grid[None, :].expand(nf, -1), *args)
        half = torch.clamp(6.0 * torch.sqrt(var), min=float(2.0 * (print_fold._GRID[1] - print_fold._GRID[0])))
        x, var = _posterior(mean[:, None] + half[:, None] * self.fine[None, :], *args)
        est = est.scatter(0, folded, x * sd)
        err = err.scatter(0, folded, var * prior[folded])
        coef = torch.cat([est, torch.zeros(1)])[place]
        r = dct.shape[0]
        planes = dct.t() @ coef.reshape(-1, r, r) @ dct
        rmse = torch.sqrt((err.sum() + prior_rest) / place.shape[0])
        return planes.reshape(3, -1, r, r), torch.stack([gain, unit * factor.mean(), rmse])
