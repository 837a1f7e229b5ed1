"""The training channel of shared copies of the 4x file (`train.codec.file_copies`): its resizes are OpenCV's,
its copies are what the bench makes with OpenCV, and gradients pass through them."""
import cv2
import numpy as np
import pytest

torch = pytest.importorskip("torch")

from snapshot3d import formats  # noqa: E402
from snapshot3d.scanner.backgrounds import load_host  # noqa: E402
from snapshot3d.train.codec.file_copies import apply_file_copies, copy_of, resize_operator  # noqa: E402

N = formats.SNAPSHOT_SIZE


@pytest.fixture(scope="module")
def snap():
    return (np.clip(load_host("builtin:coffee"), 0, 1) * 255 + 0.5).astype(np.uint8)   # (380, 380, 3) RGB


def _t(rgb):
    return torch.from_numpy(rgb.astype(np.float32) / 255).permute(2, 0, 1)[None]


def _psnr(a, b):
    return 10 * np.log10(255.0 ** 2 / np.mean((a.astype(np.float64) - b) ** 2))


def test_resize_operator_is_opencvs(snap):
    big = np.repeat(np.repeat(snap, 4, 0), 4, 1)
    for size, interp, repeat, src in ((256, cv2.INTER_AREA, 4, big), (1080, cv2.INTER_AREA, 4, big),
                                      (N, cv2.INTER_CUBIC, 1, cv2.resize(snap, (256, 256), interpolation=cv2.INTER_AREA))):
        n_in = src.shape[0] // repeat
        op = resize_operator(n_in, size, interp, repeat)
        x = src[::repeat, ::repeat].astype(np.float32)
        got = np.einsum("ph,hwc,qw->pqc", op.numpy(), x, op.numpy(), optimize=True)
        want = cv2.resize(src, (size, size), interpolation=interp).astype(np.float32)
        assert np.abs(np.clip(got, 0, 255) - want).max() <= 1.0, (size, interp)


@pytest.mark.parametrize("size,quality", [(None, 75), (256, 90), (512, 75)])
def test_copies_match_opencvs_files(snap, size, quality):
    got = (copy_of(_t(snap), size, (float(quality),))[0].permute(1, 2, 0).numpy().clip(0, 1) * 255)
    big = np.repeat(np.repeat(snap, 4, 0), 4, 1)
    if size is not None:
        big = cv2.resize(big, (size, size), interpolation=cv2.INTER_AREA)
    ok, buf = cv2.imencode(".jpg", cv2.cvtColor(big, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, quality])
    copy = cv2.cvtColor(cv2.imdecode(buf, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
    want = (cv2.resize(copy, (N, N), interpolation=cv2.INTER_CUBIC if size < N else cv2.INTER_AREA) if size
            else cv2.resize(copy, (N, N), interpolation=cv2.INTER_AREA))
    assert _psnr(got, want) > 40.0, (size, quality, _psnr(got, want))   # the copy itself is 28-36 dB from the snapshot


def test_channel_rounds_at_level_zero_and_passes_gradients(snap):
    x = _t(snap)[..., :96, :96].repeat(6, 1, 1, 1).requires_grad_(True)
    gen = torch.Generator().manual_seed(0)
    assert torch.equal(apply_file_copies(x, torch.zeros(6), generator=gen), x.detach())
    y = apply_file_copies(x, torch.ones(6), generator=gen)
    assert y.shape == x.shape and not torch.equal(y, x.detach())
    y.square().sum().backward()
    assert torch.isfinite(x.grad).all() and float(x.grad.abs().mean()) > 0


def test_copy_options_out_of_range_are_refused_in_one_line(tmp_path):
    from snapshot3d.errors import UserError
    from snapshot3d.train.codec.config import CodecConfig
    from snapshot3d.train.codec.training import train_codec

    for field, value in (("copy_resize_prob", 1.5), ("copy_shrink_share", -0.1)):
        cfg = CodecConfig(file_copies=True, **{field: value})
        with pytest.raises(UserError, match=f"--{field.replace('_', '-')} must be in"):
            train_codec(cfg, None, tmp_path / "c.npz")
    assert not any(tmp_path.iterdir())
