"""An embedded transform coder for the digital print payload (`bench.digital_ldpc`): the planes' orthonormal DCT
coefficients quantised on a uniform grid by bisection and arithmetic-coded with the carriers' prior spectrum
(numpy + pure Python; a bench candidate, not a shipped codec).

Each coefficient i (sigma_i from `print_source.prior_spectrum`) starts as the interval [-L, L] in sigma units (the
end cells reach to infinity); one decision halves a coefficient's interval at its middle (a uniform quantiser
whose step halves with each decision), coded by a binary arithmetic coder with the probability the Gaussian
prior gives to the lower half. The next coefficient to refine is the one whose decision buys the most expected
squared error per expected bit (reverse water-filling, decided on the fly by the same rule on both sides,
which see the same intervals). A stream is cut into segments of a fixed size (one per channel-code layer),
each with a 16-bit count of its decisions and flushed on its own, so the segments that arrive restore a
prefix of the refinement; every coefficient restores at the prior's mean within its interval (0 when never
refined).

Layouts: planes (3, C, R, R) float in [-1, 1]; segments uint8 0/1 bit arrays."""
from __future__ import annotations

import heapq
import math

import numpy as np

from snapshot3d.codecs import print_source

__all__ = ["encode_segments", "decode_segments", "sigmas", "RANGE_SIGMAS", "MAX_DEPTH"]

RANGE_SIGMAS = 5.0
MAX_DEPTH = 14          # decisions per coefficient at most (cells of 10 / 2^14 sigma)
_COUNT_BITS = 16
_PREC = 32
_FULL, _HALF, _QUARTER = (1 << _PREC) - 1, 1 << (_PREC - 1), 1 << (_PREC - 2)
_SQ2 = math.sqrt(2.0)


def sigmas(res: int, channels: int) -> np.ndarray:
    """(3 * C * R * R,) the prior's standard deviation of every coefficient (`plane_dct` order)."""
    return np.sqrt(np.tile(print_source.prior_spectrum(res).ravel(), 3 * channels))


def _cdf(x: float) -> float:
    return 0.5 * math.erfc(-x / _SQ2)


def _moments(a: float, b: float) -> tuple[float, float, float]:
    """Mass, mean and variance of N(0, 1) on [a, b] (the ends may be infinite)."""
    z = max(_cdf(b) - _cdf(a), 1e-300)
    pa = 0.0 if math.isinf(a) else math.exp(-0.5 * a * a) / math.sqrt(2 * math.pi)
    pb = 0.0 if math.isinf(b) else math.exp(-0.5 * b * b) / math.sqrt(2 * math.pi)
    ta = 0.0 if math.isinf(a) else a * pa
    tb = 0.0 if math.isinf(b) else b * pb
    mean = (pa - pb) / z
    return z, mean, max(1.0 + (ta - tb) / z - mean * mean, 0.0)


class _State:
    """Both sides' view of the refinement: each coefficient's grid interval, and which to refine next."""

    def __init__(self, sig: np.ndarray):
        self.sig = sig
        self.lo = [-RANGE_SIGMAS] * len(sig)
        self.hi = [RANGE_SIGMAS] * len(sig)
        self.depth = [0] * len(sig)
        self.heap = [(-self._worth(i), i) for i in range(len(sig))]
        heapq.heapify(self.heap)

    def _ends(self, i: int) -> tuple[float, float]:
        a, b = self.lo[i], self.hi[i]
        return (-math.inf if a <= -RANGE_SIGMAS else a), (math.inf if b >= RANGE_SIGMAS else b)

    def p_low(self, i: int) -> float:
        """Probability that coefficient i lies in the lower half of its interval."""
        a, b = self._ends(i)
        mid = 0.5 * (self.lo[i] + self.hi[i])
        return (_cdf(mid) - _cdf(a)) / max(_cdf(b) - _cdf(a), 1e-300)

    def _worth(self, i: int) -> float:
        """Expected squared error removed per expected bit by refining coefficient i once."""
        if self.depth[i] >= MAX_DEPTH:
            return -1.0
        a, b = self._ends(i)
        mid = 0.5 * (self.lo[i] + self.hi[i])
        z, _, var = _moments(a, b)
        z0, _, v0 = _moments(a, mid)
        z1, _, v1 = _moments(mid, b)
        p = min(max(z0 / z, 1e-12), 1 - 1e-12)
        gain = var - (p * v0 + (1 - p) * v1)
        bits = -(p * math.log2(p) + (1 - p) * math.log2(1 - p))
        return self.sig[i] ** 2 * gain / max(bits, 1e-9)

    def next(self) -> int | None:
        """The coefficient to refine next (None when nothing is worth refining)."""
        worth, i = self.heap[0]
        return None if worth >= 0 else i

    def apply(self, i: int, upper: int) -> None:
        mid = 0.5 * (self.lo[i] + self.hi[i])
        if upper:
            self.lo[i] = mid
        else:
            self.hi[i] = mid
        self.depth[i] += 1
        heapq.heapreplace(self.heap, (-self._worth(i), i))

    def values(self) -> np.ndarray:
        return np.array([self.sig[i] * _moments(*self._ends(i))[1] if self.depth[i] else 0.0
                         for i in range(len(self.sig))])


def _split(p_low: float) -> int:
    """The lower half's share of a coder interval, as a 16-bit fraction kept away from 0 and 1."""
    return min(max(int(round(p_low * 65536)), 1), 65535)


class _Encoder:
    def __init__(self):
        self.low, self.high, self.pending, self.out = 0, _FULL, 0, []

    def state(self) -> tuple:
        return self.low, self.high, self.pending, len(self.out)

    def restore(self, state: tuple) -> None:
        self.low, self.high, self.pending, n = state
        del self.out[n:]

    def _emit(self, bit: int) -> None:
        self.out.append(bit)
        self.out.extend([1 - bit] * self.pending)
        self.pending = 0

    def code(self, bit: int, p_low: float) -> None:
        span = self.high - self.low + 1
        cut = self.low + (span * _split(p_low) >> 16) - 1
        if bit:
            self.low = cut + 1
        else:
            self.high = cut
        while True:
            if self.high < _HALF:
                self._emit(0)
            elif self.low >= _HALF:
                self._emit(1)
                self.low -= _HALF
                self.high -= _HALF
            elif self.low >= _QUARTER and self.high < _HALF + _QUARTER:
                self.pending += 1
                self.low -= _QUARTER
                self.high -= _QUARTER
            else:
                break
            self.low, self.high = 2 * self.low, 2 * self.high + 1

    def flushed_len(self) -> int:
        return len(self.out) + self.pending + 2

    def flush(self) -> list[int]:
        self.pending += 1
        self._emit(0 if self.low < _QUARTER else 1)
        return self.out


class _Decoder:
    def __init__(self, bits: np.ndarray):
        self.bits, self.pos = bits, 0
        self.low, self.high, self.value = 0, _FULL, 0
        for _ in range(_PREC):
            self.value = 2 * self.value + self._bit()

    def _bit(self) -> int:
        b = int(self.bits[self.pos]) if self.pos < len(self.bits) else 0
        self.pos += 1
        return b

    def code(self, p_low: float) -> int:
        span = self.high - self.low + 1
        cut = self.low + (span * _split(p_low) >> 16) - 1
        bit = int(self.value > cut)
        if bit:
            self.low = cut + 1
        else:
            self.high = cut
        while True:
            if self.high < _HALF:
                pass
            elif self.low >= _HALF:
                self.low, self.high, self.value = self.low - _HALF, self.high - _HALF, self.value - _HALF
            elif self.low >= _QUARTER and self.high < _HALF + _QUARTER:
                self.low, self.high, self.value = self.low - _QUARTER, self.high - _QUARTER, self.value - _QUARTER
            else:
                break
            self.low, self.high = 2 * self.low, 2 * self.high + 1
            self.value = 2 * self.value + self._bit()
        return bit


def encode_segments(planes: np.ndarray, sizes: list[int]) -> list[np.ndarray]:
    """planes (3, C, R, R) -> one bit array (uint8) of exactly each size in `sizes` (the segments' payloads,
    each at least 16 + 2 bits), in refinement order."""
    _, c, r, _ = planes.shape
    sig = sigmas(r, c)
    x = print_source.plane_dct(planes) / sig
    st, out = _State(sig), []
    for size in sizes:
        enc, count, budget = _Encoder(), 0, size - _COUNT_BITS
        while count < (1 << _COUNT_BITS) - 1 and (i := st.next()) is not None:
            bit = int(x[i] >= 0.5 * (st.lo[i] + st.hi[i]))
            saved = enc.state()
            enc.code(bit, st.p_low(i))
            if enc.flushed_len() > budget:
                enc.restore(saved)
                break
            st.apply(i, bit)
            count += 1
        body = enc.flush()
        seg = np.zeros(size, np.uint8)
        seg[:_COUNT_BITS] = [(count >> (_COUNT_BITS - 1 - k)) & 1 for k in range(_COUNT_BITS)]
        seg[_COUNT_BITS:_COUNT_BITS + len(body)] = body
        out.append(seg)
    return out


def decode_segments(segments: list[np.ndarray], res: int, channels: int) -> np.ndarray:
    """The first segments of a stream (as `encode_segments` made them) -> planes (3, C, R, R) float32."""
    st = _State(sigmas(res, channels))
    for seg in segments:
        count = int("".join(str(int(b)) for b in seg[:_COUNT_BITS]), 2)
        dec = _Decoder(seg[_COUNT_BITS:])
        for _ in range(count):
            i = st.next()
            if i is None:
                break
            st.apply(i, dec.code(st.p_low(i)))
    return print_source.plane_idct(st.values(), (3, channels, res, res)).astype(np.float32)
