"""Folded carriers of the print codec `print-2` (numpy; torch-free): a non-linear code for the plane
coefficients the channel carries best.

The linear code of `print-1` gives each DCT coefficient of the planes one carrier, whose error falls only
in proportion to its power. For the few hundred coefficients with the most power (the lowest frequencies,
which also make most of a view), `print-2` keeps part of the power (`FOLD_LINEAR`) on the linear carrier
and winds the value x (in prior standard deviations) onto a helix on two more carriers, cos(k x) and
sin(k x) (k = `FOLD_TURNS`): a Shannon-Kotelnikov bandwidth-expanding map. The linear reading says roughly
where x is, the helix's phase says it finely, so the error falls faster than the power once the capture's
noise is below the threshold of the fold. The reader takes the posterior mean of x given the three
readings, with the gain and noise the pilots measure and the prior N(0, 1), so a noisy capture degrades
towards the linear reading instead of jumping between turns.

Layouts: x, readings, amplitudes and noise powers are (F,) float, one per folded coefficient."""
from __future__ import annotations

import numpy as np

__all__ = ["FOLD_CSNR_DB", "FOLD_TURNS", "FOLD_LINEAR", "helix", "unfold"]

FOLD_CSNR_DB = 5.8
"""a coefficient is folded when its design power is at least this many dB above the design noise (about
300 coefficients at every plane size the print medium carries; chosen by measurement, docs/print-codec.md "Choosing the fold")"""
FOLD_TURNS = 2.0
"""radians of the helix per prior standard deviation of the coefficient"""
FOLD_LINEAR = 0.6
"""share of a folded coefficient's power left on its linear carrier (the rest goes to the helix)"""
_GRID = np.linspace(-6.0, 6.0, 601)     # x in prior standard deviations
_FINE = np.linspace(-1.0, 1.0, 161)     # the second pass, relative to its half-width


def helix(x: np.ndarray, turns: float = FOLD_TURNS) -> tuple[np.ndarray, np.ndarray]:
    """x (F,) -> the two folded carriers' values per unit amplitude (cos(k x), sin(k x))."""
    return np.cos(turns * x), np.sin(turns * x)


def _posterior(grid, y_lin, a_lin, n_lin, y_cos, y_sin, amp, n_cos, n_sin, turns):
    """Mean and variance of x on `grid` ((F, G) or (G,)) under the readings and the prior N(0, 1)."""
    g = np.broadcast_to(grid, (len(y_lin), grid.shape[-1]))
    c, s = helix(g, turns)
    col = (lambda v: np.asarray(v, np.float64)[:, None])
    ll = (-(col(y_lin) - col(a_lin) * g) ** 2 / (2 * col(n_lin))
          - (col(y_cos) - col(amp) * c) ** 2 / (2 * col(n_cos)) - (col(y_sin) - col(amp) * s) ** 2 / (2 * col(n_sin))
          - g ** 2 / 2)
    w = np.exp(ll - ll.max(1, keepdims=True))
    w /= w.sum(1, keepdims=True)
    mean = (w * g).sum(1)
    return mean, np.maximum((w * g * g).sum(1) - mean ** 2, 0.0)


def unfold(y_lin, a_lin, n_lin, y_cos, y_sin, amp, n_cos, n_sin,
           turns: float = FOLD_TURNS) -> tuple[np.ndarray, np.ndarray]:
    """The posterior mean and variance of x (F,) from the folded coefficients' readings: y_lin (F,) read on
    the linear carrier (expected a_lin x, noise power n_lin), y_cos and y_sin (F,) on the helix (expected
    amp cos(k x) and amp sin(k x), noise powers n_cos and n_sin). A coarse grid over +-6 prior deviations, then
    a fine one over +-6 posterior deviations (exact to far below the noise even for a lossless copy)."""
    args = (y_lin, a_lin, n_lin, y_cos, y_sin, amp, n_cos, n_sin, turns)
    mean, var = _posterior(_GRID, *args)
    half = np.maximum(6.0 * np.sqrt(var), 2.0 * (_GRID[1] - _GRID[0]))
    return _posterior(mean[:, None] + half[:, None] * _FINE[None, :], *args)
