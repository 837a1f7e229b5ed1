"""The near-capacity digital payload candidate (`bench.digital_ldpc`, `bench.digital_source`, issue 37 item 3): the
IRA-LDPC code's codewords satisfy its parity checks and decode exactly at high SNR; at 1.3 dB above the
rate-1/2 BPSK limit (hard decisions 11-13 % wrong) they still decode exactly, and far below it the decoder says
it failed; the entropy-coded transform coder fills its segments exactly, restores better with each segment that
arrives and is lossless for what it sent; a clean snapshot decodes every layer; `--codes` rejects unknown codes
in one line."""
import argparse

import numpy as np
import pytest

pytest.importorskip("ldpc")

from snapshot3d.bench import digital_ldpc as dl  # noqa: E402
from snapshot3d.bench import digital_source as ds  # noqa: E402
from snapshot3d.bench.print_digital import bench_print_digital_command  # noqa: E402
from snapshot3d.errors import UserError  # noqa: E402
from snapshot3d.paths import asset  # noqa: E402
from snapshot3d.scanner.backgrounds import load_host  # noqa: E402
from snapshot3d.scene import load_scene_file  # noqa: E402


def _rmse(a, b):
    return float(np.sqrt(np.mean((a - b) ** 2)))


@pytest.fixture(scope="module")
def planes():
    return load_scene_file(asset("spot-print.s3d")).planes()


def _awgn(code, rng, esn0_db):
    info = rng.integers(0, 2, code.k)
    word = dl.ldpc_encode(code, info)
    sigma = np.sqrt(1.0 / (2.0 * 10 ** (esn0_db / 10)))
    y = 1.0 - 2.0 * word + rng.normal(0.0, sigma, code.n)
    return info, word, 2.0 * y / sigma ** 2


def test_ldpc_round_trip_at_high_snr():
    code = dl.make_code(1200, 400)
    rng = np.random.default_rng(0)
    for _ in range(3):
        info, word, llr = _awgn(code, rng, 6.0)
        assert word.shape == (1200,) and np.all(word[:400] == info)
        assert not np.any((code.h @ word.astype(np.int64)) % 2)          # a codeword
        got, ok = dl.ldpc_decode(code, llr)
        assert ok and np.array_equal(got, word)


def test_ldpc_decodes_near_capacity_and_reports_failure_below():
    code = dl.make_code(2000, 1000)
    rng = np.random.default_rng(1)
    for _ in range(3):   # rate 1/2 BPSK needs Es/N0 > -2.8 dB; at -1.5 dB about 12 % of hard decisions are wrong
        info, word, llr = _awgn(code, rng, -1.5)
        assert np.mean((llr < 0) != word) > 0.09
        got, ok = dl.ldpc_decode(code, llr)
        assert ok and np.array_equal(got[:1000], info)
    info, word, llr = _awgn(code, rng, -4.0)
    got, ok = dl.ldpc_decode(code, llr)
    assert not ok and np.any(got[:1000] != info)


def test_source_segments_are_exact_and_embedded(planes):
    sizes = [400, 800, 1600, 3200]
    segs = ds.encode_segments(planes, sizes)
    assert [len(s) for s in segs] == sizes and all(set(np.unique(s)) <= {0, 1} for s in segs)
    errors = [_rmse(ds.decode_segments(segs[:i], 16, 4), planes) for i in range(len(segs) + 1)]
    assert errors[0] == pytest.approx(_rmse(0 * planes, planes), rel=1e-6)
    assert all(b < a for a, b in zip(errors, errors[1:])), errors
    assert errors[-1] < 0.2                       # 6 kbit for 3072 values
    # the decoder follows the encoder's refinement: one segment of 6000 bits restores like the four above
    one = ds.decode_segments(ds.encode_segments(planes, [sum(sizes)]), 16, 4)
    assert _rmse(one, planes) == pytest.approx(errors[-1], rel=0.05)


def test_clean_snapshot_decodes_every_layer(planes):
    host = load_host("builtin:chelsea")
    snap = dl.embed_ldpc(host, planes)
    mse = np.mean((snap / 255.0 - host) ** 2)
    assert 10 * np.log10(1.0 / mse) == pytest.approx(32.0, abs=0.5)
    got, rd = dl.read_ldpc(snap, 16, 4, sent=dl.coded_bits(planes))
    plan = dl.layer_plan(dl.LDPC_DESIGN)
    assert rd.layers == len(plan) and rd.bits == sum(k - 16 for _, k in plan)
    assert rd.mutual_info_bits > rd.bits
    expect = ds.decode_segments(ds.encode_segments(planes, [k - 16 for _, k in plan]), 16, 4)
    assert np.allclose(got, expect, rtol=1e-6, atol=1e-6)


def test_unknown_code_is_one_line_error():
    args = argparse.Namespace(out="/tmp/unused", severities="mild", hosts="chelsea", heldout=0,
                              scenes=str(asset("spot-print.s3d")), seeds=1, size=64, codes="turbo")
    with pytest.raises(UserError, match="--codes: unknown turbo"):
        bench_print_digital_command(args)
