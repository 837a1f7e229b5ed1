"""A near-capacity digital payload for the print medium (issue 37, item 3): the embedded transform coder of
`bench.digital_source`, nested layers each with a CRC-16 and an irregular repeat-accumulate LDPC code of its own
rate, BPSK on the carriers of `bench.digital_payload` (same pool, pilots and 32 dB host), decoded by belief
propagation (the `ldpc` package, product-sum) from soft values: log-likelihood ratios from the pilots' gain and
noise per carrier (numpy + scipy + ldpc; a bench candidate, not a shipped codec).

The code: H = [A | T] (m x n), T the dual diagonal (an accumulator: parity p_j = p_(j-1) + (A u)_j, so encoding
is linear), A with `heavy_share` of the information bits of degree `heavy_degree` and the rest of degree 3,
sockets matched at random (seeded; repeated edges dropped). The decoder runs on the hard decisions' syndrome
with each bit's flip probability 1 / (1 + e^|LLR|), which is soft-input BP in the form the `ldpc` package takes.
The layers' carriers are interleaved over the pool at random, so each layer sees the capture's average channel.

Layouts: planes (3, C, R, R) float in [-1, 1]; snapshot (380, 380, 3) uint8 RGB; bits and codewords uint8 0/1;
LLRs float64, log P(0) / P(1)."""
from __future__ import annotations

import binascii
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import scipy.sparse as sp

from snapshot3d.codecs import print_carriers, print_embed, print_read, print_source
from snapshot3d.errors import UserError

from .digital_payload import carrier_pool
from .digital_source import decode_segments, encode_segments

__all__ = ["LdpcCode", "make_code", "ldpc_encode", "ldpc_decode", "LdpcDesign", "LDPC_DESIGN", "layer_plan",
           "coded_bits", "embed_ldpc", "read_ldpc", "LdpcReading", "carrier_llrs"]

_CRC_BITS = 16
_SEED = 20261126


@dataclass(frozen=True)
class LdpcCode:
    """A systematic IRA code: codeword = [info (k), parity (n - k)]; `a` the (m, k) information part of H."""

    n: int
    k: int
    a: sp.csr_matrix
    h: sp.csr_matrix


@lru_cache(maxsize=32)
def make_code(n: int, k: int, heavy_degree: int = 8, heavy_share: float = 0.2, seed: int = _SEED) -> LdpcCode:
    """An (n, k) IRA LDPC code (n > k > 0)."""
    if not 0 < k < n:
        raise ValueError(f"LDPC code needs 0 < k < n, got n={n}, k={k}")
    m = n - k
    rng = np.random.default_rng(seed + 7919 * n + k)
    deg = np.full(k, 3)
    deg[: int(round(heavy_share * k))] = heavy_degree
    cols = np.repeat(np.arange(k), deg)
    rows = rng.permutation(np.resize(np.arange(m), len(cols)))
    a = sp.csr_matrix((np.ones(len(cols), np.uint8), (rows, cols)), shape=(m, k))
    a.data[:] = 1                              # repeated edges kept once
    t = sp.eye(m, dtype=np.uint8, format="csr") + sp.eye(m, k=-1, dtype=np.uint8, format="csr")
    return LdpcCode(n, k, a, sp.hstack([a, t], format="csr"))


def ldpc_encode(code: LdpcCode, info: np.ndarray) -> np.ndarray:
    """info (k,) 0/1 -> codeword (n,) uint8 (H @ codeword = 0 mod 2)."""
    s = (code.a @ info.astype(np.int64)) % 2
    return np.concatenate([info.astype(np.uint8), (np.cumsum(s) % 2).astype(np.uint8)])


def ldpc_decode(code: LdpcCode, llr: np.ndarray, max_iter: int = 60) -> tuple[np.ndarray, bool]:
    """LLRs (n,) -> the decoded codeword (n,) uint8 and whether BP converged to one (syndrome 0)."""
    from ldpc import BpDecoder

    hard = (llr < 0).astype(np.uint8)
    flip = 1.0 / (1.0 + np.exp(np.minimum(np.abs(llr), 40.0)))
    dec = BpDecoder(code.h, error_channel=np.clip(flip, 1e-15, 0.5 - 1e-9).tolist(), max_iter=max_iter,
                    bp_method="product_sum", schedule="serial", input_vector_type="syndrome")
    syndrome = (code.h @ hard.astype(np.int64)) % 2
    err = dec.decode(syndrome.astype(np.uint8))
    return hard ^ err.astype(np.uint8), bool(dec.converge)


@dataclass(frozen=True)
class LdpcDesign:
    """carriers: data carriers (the pilots come on top); layers: (share of the data carriers, code rate) of each
    nested layer, most protected first; heavy_degree, heavy_share: the information bits' degree profile."""

    carriers: int = 12000
    layers: tuple = ((0.25, 0.2), (0.25, 1 / 3), (0.25, 0.5), (0.25, 2 / 3))
    heavy_degree: int = 8
    heavy_share: float = 0.2


LDPC_DESIGN = LdpcDesign()


def layer_plan(design: LdpcDesign) -> list[tuple[int, int]]:
    """(code length n, information bits k incl. the CRC) of each layer."""
    out, left = [], design.carriers
    for i, (share, rate) in enumerate(design.layers):
        n = left if i == len(design.layers) - 1 else int(round(share * design.carriers))
        left -= n
        k = int(round(rate * n))
        if k <= _CRC_BITS + 18 or k >= n:
            raise UserError(f"LDPC layer {i}: {n} carriers at rate {rate:.3f} leave no room for a payload")
        out.append((n, k))
    return out


@lru_cache(maxsize=4)
def _interleave(carriers: int) -> np.ndarray:
    return np.random.default_rng(_SEED + carriers).permutation(carriers)


def _crc(bits: np.ndarray) -> np.ndarray:
    return np.unpackbits(np.frombuffer(binascii.crc_hqx(np.packbits(bits).tobytes(), 0).to_bytes(2, "big"), np.uint8))


def _code(design: LdpcDesign, n: int, k: int) -> LdpcCode:
    return make_code(n, k, design.heavy_degree, design.heavy_share)


def coded_bits(planes: np.ndarray, design: LdpcDesign = LDPC_DESIGN) -> np.ndarray:
    """planes (3, C, R, R) -> the data carriers' coded bits (carriers,) uint8, in carrier order."""
    plan = layer_plan(design)
    segs = encode_segments(planes, [k - _CRC_BITS for _, k in plan])
    words = [ldpc_encode(_code(design, n, k), np.concatenate([s, _crc(s)])) for s, (n, k) in zip(segs, plan)]
    out = np.zeros(design.carriers, np.uint8)
    out[_interleave(design.carriers)] = np.concatenate(words)
    return out


def embed_ldpc(host: np.ndarray, planes: np.ndarray, design: LdpcDesign = LDPC_DESIGN,
               host_psnr: float = print_source.HOST_PSNR) -> np.ndarray:
    """host (380, 380, 3) float RGB in [0, 1], planes (3, C, R, R) -> snapshot (380, 380, 3) uint8 RGB at
    `host_psnr` dB from the host."""
    lay = carrier_pool(design.carriers)
    unit = np.concatenate([lay.pilot_signs, 1.0 - 2.0 * coded_bits(planes, design)])
    return print_embed.embed_values(host, lay, unit, host_psnr)[0]


def carrier_llrs(capture: np.ndarray, carriers: int) -> tuple[np.ndarray, float]:
    """A rectified capture (380, 380, 3) uint8 RGB -> the data carriers' LLRs (carriers,) from the pilots' gain
    and noise, and their mean SNR (dB)."""
    lay = carrier_pool(carriers)
    read, factor = print_read.read_carriers(capture, lay)
    p = read[:print_carriers.PILOTS] * lay.pilot_signs
    gain = max(float(np.mean(p)), 1e-9)
    unit = max(float(np.mean((p - gain) ** 2 / factor[:print_carriers.PILOTS])), 1e-12)
    f = factor[print_carriers.PILOTS:]
    snr = gain ** 2 / (unit * float(np.mean(f)))
    return 2.0 * gain * read[print_carriers.PILOTS:] / (unit * f), float(10 * np.log10(snr))


@dataclass(frozen=True)
class LdpcReading:
    layers: int
    """nested layers that decoded with their CRC holding"""
    bits: int
    """payload bits restored (the layers' information bits less their CRCs)"""
    snr_db: float
    """the data carriers' mean SNR the pilots measure"""
    mutual_info_bits: float
    """the BPSK mutual information of the data carriers' soft values (needs the sent bits; NaN without)"""


def read_ldpc(capture: np.ndarray, res: int, channels: int, design: LdpcDesign = LDPC_DESIGN,
              sent: np.ndarray | None = None) -> tuple[np.ndarray, LdpcReading]:
    """A rectified capture (380, 380, 3) uint8 RGB -> planes (3, C, R, R) float32 and what was read. `sent`: the
    data carriers' coded bits (`coded_bits`), to measure the mutual information (bench only)."""
    llr_all, snr = carrier_llrs(capture, design.carriers)
    llr = llr_all[_interleave(design.carriers)]
    segs, start = [], 0
    for n, k in layer_plan(design):
        word, ok = ldpc_decode(_code(design, n, k), llr[start:start + n])
        start += n
        info = word[:k]
        if not ok or not np.array_equal(_crc(info[:-_CRC_BITS]), info[-_CRC_BITS:]):
            break
        segs.append(info[:-_CRC_BITS])
    mi = float("nan")
    if sent is not None:
        s = 1.0 - 2.0 * sent
        mi = float(np.sum(1.0 - np.logaddexp(0.0, -np.clip(llr_all * s, -60, 60)) / np.log(2.0)))
    planes = decode_segments(segs, res, channels)
    return planes, LdpcReading(len(segs), int(sum(len(s) for s in segs)), snr, mi)
