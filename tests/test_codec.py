"""The codec: invertibility, the plane layout, the channel, and the shipped weights' round trip."""
import numpy as np
import pytest
import torch

from snapshot3d import formats
from snapshot3d.codecs import file_layout
from snapshot3d.train.codec.channel import apply_channel, round_8bit
from snapshot3d.train.codec.net import CodecNet, haar, ihaar


def _smooth_planes(rng, c=8, r=64):
    import cv2
    coarse = rng.uniform(-0.8, 0.8, (3 * c, 8, 8)).astype(np.float32)
    return np.stack([cv2.resize(p, (r, r), interpolation=cv2.INTER_CUBIC) for p in coarse]).reshape(3, c, r, r).clip(-1, 1)


def test_haar_round_trip_and_orthonormal():
    x = torch.rand(2, 3, 38, 38, dtype=torch.float64)
    y = haar(x)
    assert y.shape == (2, 12, 19, 19)
    assert torch.allclose(ihaar(y), x, atol=1e-12)
    assert torch.allclose(y.square().sum(), x.square().sum())  # energy preserved
    assert torch.allclose(y[:, :3], 2 * torch.nn.functional.avg_pool2d(x, 2))  # LL band is the local mean


def test_codec_net_inverts_with_true_z_float64():
    torch.manual_seed(0)
    net = CodecNet(24, blocks=3, width=8, layers=3, clamp=1.0).double()
    for p in net.parameters():  # leave the zero init: an identity network would prove nothing
        torch.nn.init.normal_(p, std=0.05)
    host, secret = torch.rand(1, 3, 64, 64, dtype=torch.float64), torch.randn(1, 24, 32, 32, dtype=torch.float64)
    snap, z = net(host, secret)
    assert snap.shape == host.shape and z.shape == secret.shape
    assert (snap - host).abs().max() > 1e-3
    host_back, secret_back = net.reverse(snap, z)
    assert (host_back - host).abs().max() <= 1e-5 and (secret_back - secret).abs().max() <= 1e-5
    assert torch.equal(net.reverse_secret(snap), net.reverse(snap)[1])  # the refinement's shortcut


@pytest.mark.parametrize("res,ch", [(64, 8), (48, 8), (32, 4)])
def test_layout_round_trip(rng, res, ch):
    planes = rng.uniform(-1, 1, (3, ch, res, res)).astype(np.float32)
    secret = file_layout.planes_to_secret(planes)
    assert secret.shape == (file_layout.SECRET_CHANNELS, formats.CODEC_GRID, formats.CODEC_GRID)
    assert np.abs(file_layout.secret_to_planes(secret, res, ch) - planes).max() < 1e-4
    assert np.all(secret.reshape(3, formats.CODEC_CHANNELS, -1)[:, ch:] == 0)  # unused channels stay empty


def test_layout_refuses_too_big_planes():
    with pytest.raises(ValueError, match="at most 8 channels"):
        file_layout.planes_to_secret(np.zeros((3, 12, 64, 64), np.float32))
    with pytest.raises(ValueError, match="64x64"):
        file_layout.planes_to_secret(np.zeros((3, 8, 96, 96), np.float32))


def test_noise_estimate_tracks_true_error(rng):
    planes = _smooth_planes(rng)
    secret = file_layout.planes_to_secret(planes)
    for sigma in (0.02, 0.1):
        noisy = secret + rng.normal(0, sigma, secret.shape).astype(np.float32)
        true = np.sqrt(np.mean((file_layout.secret_to_planes(noisy, 64, 8) - planes) ** 2))
        est = file_layout.noise_estimate(noisy, 64, 8)
        assert 0.8 < est / true < 1.25, (sigma, est, true)
    assert file_layout.noise_estimate(secret, 64, 8) < 1e-4


def test_channel_level_zero_is_8bit_only_and_level_one_hurts():
    gen = torch.Generator().manual_seed(0)
    x = torch.nn.functional.interpolate(torch.rand(4, 3, 12, 12, generator=gen), size=(96, 96), mode="bilinear")
    y0 = apply_channel(x, torch.zeros(4), generator=gen)
    assert (y0 - x).abs().max() <= 0.5 / 255 + 1e-6
    x.requires_grad_(True)
    y1 = apply_channel(x, torch.ones(4), generator=gen)
    assert y1.shape == x.shape and 0 <= float(y1.detach().min()) and float(y1.detach().max()) <= 1
    assert 0.02 < float((y1 - x).detach().square().mean().sqrt()) < 0.3
    y1.sum().backward()
    assert x.grad is not None and float(x.grad.abs().mean()) > 0.1  # differentiable end to end


def test_sharing_channel_is_real_jpeg_sized_and_differentiable():
    """The file codec's sharing channel: level 0 is 8-bit rounding only; at level 1 a JPEG copy costs what
    OpenCV's JPEG 95..60 (4:2:0) costs the same image, a resized copy comes back at the input's size, and the
    gradient reaches the input."""
    import cv2

    from snapshot3d.train.codec.channel import SharingRanges, apply_sharing
    gen = torch.Generator().manual_seed(0)
    rng = np.random.default_rng(0)
    img = cv2.resize(rng.uniform(0, 1, (24, 24, 3)).astype(np.float32), (96, 96), interpolation=cv2.INTER_CUBIC)
    img = np.clip(img + rng.normal(0, 0.03, img.shape), 0, 1).astype(np.float32)
    x = torch.from_numpy(img.transpose(2, 0, 1))[None].repeat(6, 1, 1, 1)
    assert (apply_sharing(x, torch.zeros(6), generator=gen) - x).abs().max() <= 0.5 / 255 + 1e-6

    def rms(a, b):
        return float(np.sqrt(np.mean((np.asarray(a, np.float64) - b) ** 2)))
    u8 = (img * 255 + 0.5).astype(np.uint8)
    cv = {q: rms(cv2.imdecode(cv2.imencode(".jpg", u8, [cv2.IMWRITE_JPEG_QUALITY, q])[1], 1) / 255.0, img) for q in (95, 60)}
    y = apply_sharing(x, torch.ones(6), SharingRanges(jpeg_prob=1.0, twice_prob=0.0, resize_prob=0.0), gen)
    errs = [rms(y[i].permute(1, 2, 0).numpy(), img) for i in range(6)]
    assert 0.7 * cv[95] < min(errs) and max(errs) < 1.4 * cv[60], (errs, cv)
    x.requires_grad_(True)
    y = apply_sharing(x, torch.ones(6), SharingRanges(resize_prob=1.0), gen)
    assert y.shape == x.shape and 0.003 < rms(y.detach().numpy(), x.detach().numpy()) < 0.2
    y.sum().backward()
    assert float(x.grad.abs().mean()) > 0.1


def test_unreadable_training_host_is_named(tmp_path):
    from snapshot3d.errors import UserError
    from snapshot3d.train.codec.print_data import host_name, read_host
    bad = tmp_path / "broken.jpg"
    bad.write_bytes(b"not a jpeg")
    with pytest.raises(UserError, match="broken.jpg"):
        read_host(str(bad))
    assert host_name(str(bad)) == "broken" and host_name("builtin:coffee") == "coffee"
    assert read_host("builtin:coffee").dtype == np.uint8


def test_round_8bit_straight_through():
    x = torch.tensor([0.1234, 0.9999, 1.3, -0.2], requires_grad=True)
    y = round_8bit(x)
    assert torch.allclose(y, torch.tensor([31 / 255, 1.0, 1.0, 0.0]))
    y.sum().backward()
    assert torch.all(x.grad == 1)


def test_fine_tune_refuses_another_architecture(tmp_path):
    from snapshot3d.errors import UserError
    from snapshot3d.train.codec.config import CodecConfig
    from snapshot3d.train.codec.hinet import codec_path
    from snapshot3d.train.codec.training import train_codec
    with pytest.raises(UserError, match="another architecture"):
        train_codec(CodecConfig(blocks=2, init=str(codec_path())), None, tmp_path / "x.npz")
    with pytest.raises(UserError, match="jpeg-prob"):
        train_codec(CodecConfig(jpeg_prob=1.5), None, tmp_path / "x.npz")
    with pytest.raises(UserError, match="not found"):
        train_codec(CodecConfig(init=str(tmp_path / "missing.npz")), None, tmp_path / "x.npz")
    assert not (tmp_path / "x.npz").exists()
