"""The capacity yardstick (`bench.capacity_model`) and the oracle scanner (`bench.oracle`) of `bench capacity`."""
import cv2
import numpy as np
import pytest

from snapshot3d.bench import capacity_model as capacity
from snapshot3d.bench.capacity_model import psnr_at
from snapshot3d.bench.oracle import oracle_correct
from snapshot3d.metrics import psnr


def test_subbands_are_orthonormal_and_check_the_size(rng):
    img = rng.uniform(0, 1, (48, 64, 3))
    bands = capacity.subbands(img)
    assert len(bands) == 3 * (3 * capacity.LEVELS + 1)
    assert sum(b.size for b in bands) == img.size
    assert np.isclose(sum(float(b @ b) for b in bands), float(np.sum(img ** 2)))
    with pytest.raises(ValueError, match="multiples of 8"):
        capacity.subbands(img[:44])


def test_fit_channel_recovers_gain_and_noise(rng):
    x = rng.uniform(0, 1, (64, 64, 3))
    y = 0.6 * x + rng.normal(0, 0.03, x.shape)
    g, n, count = capacity.fit_channel(x, y)
    assert np.allclose(g, 0.6, atol=0.08) and np.allclose(n, 0.03 ** 2, rtol=0.4)
    assert int(count.sum()) == x.size
    _, n0, _ = capacity.fit_channel(x, x)
    assert np.allclose(n0, capacity.QUANT_NOISE)  # a lossless capture keeps the 8-bit floor


def test_waterfill_known_case_and_budget():
    s = capacity.waterfill(np.array([1.0, 2.0, 10.0]), np.array([1, 1, 1]), 2.0)
    assert np.allclose(s, [1.5, 0.5, 0.0])
    s = capacity.waterfill(np.array([1.0, 3.0]), np.array([10, 30]), 100.0)
    assert np.isclose(float(np.sum(np.array([10, 30]) * s)), 100.0) and np.isclose(s[0] + 1.0, s[1] + 3.0)


def test_capacity_of_white_noise_is_shannons_and_grows_with_visibility():
    n = np.full(4, 1e-3)
    count = np.array([100, 200, 300, 400])
    gain = np.ones(4)
    bits = capacity.capacity_bits(gain, n, count, 30.0)
    assert np.isclose(bits, 1000 * 0.5 * np.log2(1 + 1e-3 / 1e-3))
    assert capacity.capacity_bits(gain, n, count, 34.0) < bits < capacity.capacity_bits(gain, n, count, 26.0)
    assert capacity.capacity_bits(gain * 0.5, n, count, 30.0) < bits  # a weaker channel carries less


def test_best_plane_rmse_follows_rate_distortion():
    assert np.isclose(capacity.best_plane_rmse(0, 100, 0.25), 0.5)
    assert np.isclose(capacity.best_plane_rmse(100, 100, 0.25), 0.25)  # one bit per value halves the error


def test_psnr_at_interpolates_in_log_error_and_clamps():
    curve = [(0.01, 50.0), (0.1, 30.0), (1.0, 10.0)]
    assert np.isclose(psnr_at(curve, np.sqrt(0.01 * 0.1)), 40.0)
    assert psnr_at(curve, 1e-5) == 50.0 and psnr_at(curve, 5.0) == 10.0


def test_oracle_removes_misregistration_and_tone(rng):
    base = cv2.resize(rng.uniform(0, 255, (24, 24, 3)).astype(np.float32), (96, 96), interpolation=cv2.INTER_CUBIC)
    sent = np.clip(base, 0, 255).astype(np.uint8)
    shift = np.float32([[1, 0, 0.6], [0, 1, -0.4]])
    seen = cv2.warpAffine(sent.astype(np.float32), shift, (96, 96), flags=cv2.INTER_CUBIC, borderMode=cv2.BORDER_REFLECT)
    seen = np.clip(seen * 0.85 + 12, 0, 255).astype(np.uint8)
    fixed = oracle_correct(seen, sent)
    assert fixed.shape == sent.shape and fixed.dtype == np.uint8
    inner = (slice(4, -4), slice(4, -4))
    assert psnr(fixed[inner] / 255, sent[inner] / 255) > psnr(seen[inner] / 255, sent[inner] / 255) + 8
