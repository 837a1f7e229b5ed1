"""A digital payload for the print medium, the candidate issue 12 asks to measure against the designed analog
carriers (`snapshot3d.codecs.print_carriers`): the planes quantised and sent as bits with error correction and a CRC,
on the same spread-spectrum carriers, the same host cancellation and the same 32 dB host (numpy; a bench
candidate, not a shipped codec).

Source coding (embedded, so that a capture that carries less still restores something): each plane
channel's orthonormal DCT coefficient i is mapped to an 8-bit index over [-4 s_i, 4 s_i] (s_i from the
carriers' prior spectrum `print_source.prior_spectrum`); its bit-planes are sent most significant first,
all coefficients' bit-planes in order of what each is worth (s_i^2 4^-p: reverse water-filling by
bit-planes). Whatever prefix arrives restores every coefficient at the middle of the interval its known
bits leave (0 where none arrived, the prior's mean).

Channel coding: the bitstream is cut into nested layers, each with its own CRC-16 (CCITT, `binascii.
crc_hqx`) and the rate-1/2, K=7 convolutional code of the pixel mark (`scanner.pixelmeta`), each coded bit
repeated over `repeats` carriers (BPSK, +1 for a 0), the first layers repeated most: a weak capture
decodes the first layers only. The reader weighs each carrier by the gain and the noise its pilots
measure (soft values = log-likelihood ratios up to a factor), sums the repetitions, runs the Viterbi
decoder and keeps layers up to the first whose CRC fails.

The near-capacity candidate on the same carriers (IRA-LDPC layers, soft BP decoding, an entropy-coded transform
coder) is `bench.digital_ldpc`.

Layouts: planes (3, C, R, R) float in [-1, 1]; snapshot (380, 380, 3) uint8 RGB; bits uint8 0/1."""
from __future__ import annotations

import binascii
import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from snapshot3d.codecs import print_carriers, print_embed, print_read, print_source
from snapshot3d.scanner.pixelmeta import conv_encode, viterbi

__all__ = ["DigitalDesign", "DESIGN", "embed_digital", "read_digital", "DigitalReading", "source_order", "carrier_pool",
           "encode_source", "decode_source", "layer_sizes"]

INDEX_BITS = 8
RANGE_SIGMAS = 4.0
_CRC_BITS = 16
_TAIL = 6            # the convolutional code's zero tail (K - 1)
_SEED = 20261124


@dataclass(frozen=True)
class DigitalDesign:
    """carriers: data carriers (the pilots, `print_carriers.PILOTS`, come on top); layers: (share of the data
    carriers, repetitions per coded bit) of each nested layer, most protected first."""

    carriers: int = 12000
    layers: tuple = ((0.1, 16), (0.15, 8), (0.25, 4), (0.25, 2), (0.25, 1))


DESIGN = DigitalDesign()


def layer_sizes(design: DigitalDesign) -> list[tuple[int, int, int]]:
    """(carriers, repetitions, information bits) of each layer."""
    out, left = [], design.carriers
    for i, (share, rep) in enumerate(design.layers):
        n = left if i == len(design.layers) - 1 else int(round(share * design.carriers))
        left -= n
        out.append((n, rep, max(0, (n // rep) // 2 - _TAIL - _CRC_BITS)))
    return out


@lru_cache(maxsize=8)
def _carriers(count: int) -> print_carriers.PrintLayout:
    """Pilots + `count` data carriers (the print codec's pool; values are all +-1)."""
    rng = np.random.default_rng(_SEED + count)
    chips, base = print_carriers.carrier_chips(print_carriers.PILOTS + count, rng)
    return print_carriers.PrintLayout(0, 0, chips, base, np.zeros(0, int), np.zeros(0), np.zeros(0), 1.0,
                          rng.choice([-1.0, 1.0], size=print_carriers.PILOTS))


def carrier_pool(count: int) -> print_carriers.PrintLayout:
    """The pilots + `count` data carriers both digital candidates write (this one and `bench.digital_ldpc`)."""
    return _carriers(count)


def _sigmas(res: int, channels: int) -> np.ndarray:
    return np.sqrt(np.tile(print_source.prior_spectrum(res).ravel(), 3 * channels))


def source_order(res: int, channels: int) -> tuple[np.ndarray, np.ndarray]:
    """(coefficient, bit-plane) of each bit of the stream (both (M * INDEX_BITS,) int), most worth first."""
    s2 = _sigmas(res, channels) ** 2
    coef = np.repeat(np.arange(len(s2)), INDEX_BITS)
    plane = np.tile(np.arange(INDEX_BITS), len(s2))
    worth = s2[coef] * 4.0 ** -plane
    order = np.lexsort((plane, coef, -worth))
    return coef[order], plane[order]


def encode_source(planes: np.ndarray) -> np.ndarray:
    """planes (3, C, R, R) -> the embedded bitstream (M * INDEX_BITS,) uint8."""
    _, c, r, _ = planes.shape
    sig = _sigmas(r, c)
    levels = 1 << INDEX_BITS
    idx = np.clip(np.floor((print_source.plane_dct(planes) + RANGE_SIGMAS * sig) / (2 * RANGE_SIGMAS * sig) * levels), 0, levels - 1)
    coef, plane = source_order(r, c)
    return ((idx.astype(np.int64)[coef] >> (INDEX_BITS - 1 - plane)) & 1).astype(np.uint8)


def decode_source(bits: np.ndarray, res: int, channels: int) -> np.ndarray:
    """The first len(bits) bits of a stream -> planes (3, C, R, R) float32 (the middle of each coefficient's
    known interval; 0 where no bit arrived)."""
    sig = _sigmas(res, channels)
    coef, plane = source_order(res, channels)
    n = len(bits)
    known = np.bincount(coef[:n], minlength=len(sig))          # a prefix of each coefficient's planes
    idx = np.zeros(len(sig), np.int64)
    np.add.at(idx, coef[:n], bits.astype(np.int64) << (INDEX_BITS - 1 - plane[:n]))
    width = 2 * RANGE_SIGMAS / (1 << known)                      # in units of each coefficient's sigma
    top = idx >> (INDEX_BITS - known)                            # the known bits as an integer
    lo = -RANGE_SIGMAS + top * width
    value = sig * _gauss_mean(np.where(top == 0, -np.inf, lo), np.where(top == (1 << known) - 1, np.inf, lo + width))
    return print_source.plane_idct(value, (3, channels, res, res)).astype(np.float32)


def _gauss_mean(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """E[x | a < x < b] for x ~ N(0, 1) (the ends may be infinite): the reconstruction a prior-aware decoder
    makes of a coefficient whose known bits leave it in [a, b] (sigma units)."""
    pdf = np.exp(-0.5 * np.minimum(np.square(a), 1e4)), np.exp(-0.5 * np.minimum(np.square(b), 1e4))
    cdf = _phi(a), _phi(b)
    mass = np.maximum(cdf[1] - cdf[0], 1e-300)
    return (pdf[0] - pdf[1]) / np.sqrt(2 * np.pi) / mass


def _phi(x: np.ndarray) -> np.ndarray:
    return 0.5 * (1.0 + np.vectorize(math.erf)(np.asarray(x, np.float64) / math.sqrt(2.0)))


def _crc(bits: np.ndarray) -> np.ndarray:
    return np.unpackbits(np.frombuffer(binascii.crc_hqx(np.packbits(bits).tobytes(), 0).to_bytes(2, "big"), np.uint8))


def _channel_bits(stream: np.ndarray, design: DigitalDesign) -> np.ndarray:
    """The data carriers' coded bits (carriers,): each layer's slice of the stream (zero-padded), its CRC,
    the convolutional code, repeated cyclically over the layer's carriers."""
    out, pos = [], 0
    for n, rep, info in layer_sizes(design):
        part = np.zeros(info, np.uint8)
        take = stream[pos:pos + info]
        part[:len(take)] = take
        pos += info
        coded = conv_encode(np.concatenate([part, _crc(part)]).astype(int))
        out.append(np.resize(coded, n))
    return np.concatenate(out)


def embed_digital(host: np.ndarray, planes: np.ndarray, design: DigitalDesign = DESIGN,
                  host_psnr: float = print_source.HOST_PSNR) -> np.ndarray:
    """host (380, 380, 3) float RGB in [0, 1], planes (3, C, R, R) -> snapshot (380, 380, 3) uint8 RGB at
    `host_psnr` dB from the host."""
    lay = _carriers(design.carriers)
    coded = _channel_bits(encode_source(planes), design)
    unit = np.concatenate([lay.pilot_signs, 1.0 - 2.0 * coded])
    return print_embed.embed_values(host, lay, unit, host_psnr)[0]


@dataclass(frozen=True)
class DigitalReading:
    layers: int
    """nested layers whose CRC held"""
    bits: int
    """stream bits restored"""
    snr_db: float
    """the data carriers' mean SNR the pilots measure"""
    mutual_info_bits: float
    """what an ideal code could carry on these carriers in this capture: the sum over data carriers of the
    BPSK mutual information given their soft values (needs the sent bits; NaN when not given)"""


def read_digital(capture: np.ndarray, res: int, channels: int, design: DigitalDesign = DESIGN,
                 sent: np.ndarray | None = None) -> tuple[np.ndarray, DigitalReading]:
    """A rectified capture (380, 380, 3) uint8 RGB -> planes (3, C, R, R) float32 and what was read.
    `sent`: the data carriers' coded bits, to measure the mutual information (bench only)."""
    lay = _carriers(design.carriers)
    read, factor = print_read.read_carriers(capture, lay)
    p = read[:print_carriers.PILOTS] * lay.pilot_signs
    gain = max(float(np.mean(p)), 1e-9)
    unit = max(float(np.mean((p - gain) ** 2 / factor[:print_carriers.PILOTS])), 1e-12)
    llr = 2.0 * gain * read[print_carriers.PILOTS:] / (unit * factor[print_carriers.PILOTS:])    # log P(0) / P(1)
    bits, layers, start = [], 0, 0
    for n, rep, info in layer_sizes(design):
        coded_len = 2 * (info + _CRC_BITS + _TAIL)
        soft = np.bincount(np.arange(n) % coded_len, weights=llr[start:start + n], minlength=coded_len)
        start += n
        dec = viterbi(soft)
        if info == 0 or not np.array_equal(_crc(dec[:info]), dec[info:]):
            break
        bits.append(dec[:info])
        layers += 1
    stream = np.concatenate(bits) if bits else np.zeros(0, np.uint8)
    stream = stream[:3 * channels * res * res * INDEX_BITS]
    mi = float("nan")
    if sent is not None:
        s = 1.0 - 2.0 * sent
        mi = float(np.sum(1.0 - np.logaddexp(0.0, -np.clip(llr * s, -60, 60)) / np.log(2.0)))
    snr = gain ** 2 / (unit * float(np.mean(factor[print_carriers.PILOTS:])))
    return decode_source(stream, res, channels), DigitalReading(layers, len(stream), float(10 * np.log10(snr)), mi)


def sent_bits(planes: np.ndarray, design: DigitalDesign = DESIGN) -> np.ndarray:
    """The data carriers' coded bits (carriers,) of planes (what `read_digital(sent=...)` compares with)."""
    return _channel_bits(encode_source(planes), design)
