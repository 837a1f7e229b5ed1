"""The refinement's differentiable JPEG against OpenCV's real files (and kornia's, which it replaced there)."""
import cv2
import kornia
import numpy as np
import pytest
import torch

from snapshot3d.metrics import psnr
from snapshot3d.scanner.backgrounds import load_host
from snapshot3d.train.codec.jpeg import jpeg_420, quant_tables


def test_quant_tables_are_libjpegs():
    t = quant_tables(torch.tensor([50.0, 75.0, 95.0, 10.0]))
    assert t[0, 0, 0, 0] == 16 and t[0, 1, 7, 7] == 99          # quality 50: Annex K as printed
    assert t[1, 0, 0, 0] == 8 and t[1, 0, 7, 7] == 50 and t[1, 1, 0, 0] == 9   # floor((T * 50 + 50) / 100)
    assert t[2, 0, 0, 0] == 2 and t[2].min() >= 1                # (T * 10 + 50) / 100, at least 1
    assert t[3, 1, 7, 7] == 255                                  # clipped to 8 bits


@pytest.mark.parametrize("quality", [60, 75, 95])
def test_jpeg_matches_opencv_files(quality):
    """OpenCV's JPEG (4:2:0) of a real photo, decoded: ours is within 43 dB of it, and nearer than kornia's."""
    rgb = (load_host("builtin:coffee") * 255 + 0.5).astype(np.uint8)
    ok, buf = cv2.imencode(".jpg", rgb[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, quality])
    real = cv2.imdecode(buf, cv2.IMREAD_COLOR)[..., ::-1].astype(np.float32) / 255
    x = torch.from_numpy(rgb.transpose(2, 0, 1).astype(np.float32) / 255)[None]
    q = torch.tensor([float(quality)])
    ours = jpeg_420(x, q).clamp(0, 1)[0].permute(1, 2, 0).numpy()
    theirs = kornia.enhance.jpeg_codec_differentiable(x, q).clamp(0, 1)[0].permute(1, 2, 0).numpy()
    assert ours.shape == real.shape
    assert psnr(ours, real) >= 43.0, psnr(ours, real)            # 44.4-46.3 dB here
    assert psnr(ours, real) >= psnr(theirs, real) + 0.3, (psnr(ours, real), psnr(theirs, real))
    assert psnr(ours, rgb / 255) < 45.0                           # it did compress


def test_jpeg_pads_like_libjpeg_and_passes_gradients():
    x = torch.rand(2, 3, 37, 50, requires_grad=True)
    y = jpeg_420(x, torch.tensor([75.0, 90.0]))
    assert y.shape == x.shape
    y.square().mean().backward()
    assert x.grad is not None and x.grad.abs().sum() > 0


@pytest.mark.parametrize("scale", [2, 4])
def test_jpeg_of_a_file_at_scale_is_the_upsampled_jpeg(scale):
    """`scale`: the JPEG of the image upsampled (nearest) that many times, read back by block means, computed at
    the image's own size; equal to doing it the long way (up to a rounding that float order may tip)."""
    torch.manual_seed(0)
    x = torch.rand(2, 3, 40, 56)
    q = torch.tensor([75.0, 90.0])
    up = x.repeat_interleave(scale, 2).repeat_interleave(scale, 3)
    want = torch.nn.functional.avg_pool2d(jpeg_420(up, q), scale)
    got = jpeg_420(x, q, scale)
    assert got.shape == x.shape
    assert (got - want).abs().mean() < 1e-5 and (got - want).abs().max() < 2e-3
    assert (got - jpeg_420(x, q)).abs().mean() > 1e-3          # not the snapshot-size JPEG
    with pytest.raises(ValueError, match="scale"):
        jpeg_420(x, q, 3)
