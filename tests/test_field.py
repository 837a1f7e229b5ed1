"""The field's functional core: compositing, plane sampling, ray-box clipping, empty-space skipping."""
import numpy as np
import torch

from snapshot3d import formats
from snapshot3d.train.field.field import (
    Decoder,
    TriPlanes,
    composite,
    decode,
    sample_planes,
    straight_through_8bit,
)
from snapshot3d.train.field.render import occupancy_from_planes, render_rays
from snapshot3d.train.field.sampler import BoxFrame, march, ray_box


def test_transmittance_cumsum_equals_cumprod():
    g = torch.Generator().manual_seed(0)
    sigma = torch.rand(64, 100, generator=g, dtype=torch.float64) * 30
    delta = 0.02
    rgb = torch.rand(64, 100, 3, generator=g, dtype=torch.float64)
    _, acc, w = composite(sigma, rgb, delta)
    alpha = 1 - torch.exp(-sigma * delta)
    trans = torch.cumprod(torch.cat([torch.ones(64, 1, dtype=torch.float64), 1 - alpha[:, :-1]], 1), 1)
    assert torch.max(torch.abs(w - trans * alpha)) < 1e-6
    assert torch.max(torch.abs(acc - (1 - torch.prod(1 - alpha, 1)))) < 1e-6


def test_composite_over_white_background():
    color, acc, _ = composite(torch.zeros(2, 5), torch.zeros(2, 5, 3), 0.1)
    assert torch.all(color == 1.0) and torch.all(acc == 0)
    color, acc, _ = composite(torch.full((1, 5), 1e4), torch.full((1, 5, 3), 0.25), 0.1)
    assert torch.allclose(color, torch.tensor(0.25)) and torch.allclose(acc, torch.tensor(1.0))


def test_sample_planes_hits_texel_centres_and_interpolates():
    planes = torch.zeros(3, 2, 3, 3)
    planes[0, 0] = torch.arange(9.0).view(3, 3)  # xy plane, rows follow y, columns x
    xyz = torch.tensor([[-1.0, -1.0, 0.3], [1.0, -1.0, 0.0], [0.0, 1.0, 0.0], [-0.5, 0.0, 0.0]])
    f = sample_planes(planes, xyz)
    assert f.shape == (4, 3, 2)
    np.testing.assert_allclose(f[:, 0, 0].numpy(), [0.0, 2.0, 7.0, 3.5], atol=1e-6)
    assert torch.all(f[:, 1:] == 0)


def test_ray_box_clipping():
    o = torch.tensor([[-3.0, 0.0, 0.0], [0.0, 0.0, 0.0], [-3.0, 5.0, 0.0]])
    d = torch.tensor([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
    near, far = ray_box(o, d, torch.tensor([1.0, 1.0, 0.5]))
    np.testing.assert_allclose(near[:2].numpy(), [2.0, 0.0]), np.testing.assert_allclose(far[:2].numpy(), [4.0, 0.5])
    assert near[2] >= far[2]  # misses


def test_straight_through_rounds_to_codes_with_identity_gradient():
    p = torch.tensor([-1.2, -0.5, 0.0031, 0.999], requires_grad=True)
    q = straight_through_8bit(p)
    codes = (q.detach() + 1) / 2 * 255
    assert torch.allclose(codes, codes.round(), atol=1e-4) and q[0] == -1.0
    q.sum().backward()
    assert torch.all(p.grad == 1)


def test_decoder_reads_fewer_channels_as_zeros():
    dec = Decoder()
    f = torch.randn(10, 3, 4)
    padded = torch.cat([f, torch.zeros(10, 3, formats.C_MAX - 4)], -1)
    s1, c1 = decode(f, dec)
    s2, c2 = decode(padded, dec)
    assert torch.allclose(s1, s2, rtol=1e-5) and torch.allclose(c1, c2, atol=1e-6)


def test_empty_space_skipping_does_not_change_the_image():
    """Rendering with the occupancy grid computed from the planes equals rendering every sample."""
    torch.manual_seed(0)
    dec = Decoder()
    with torch.no_grad():  # density exp(-7) (empty) except where channel 0 of all three planes is near 1
        dec.l0.weight[0] = 0.0
        dec.l0.weight.view(-1, 3, formats.C_MAX)[0, :, 0] = 1.0
        dec.l0.bias[0] = -2.5
        dec.l1.weight[0] = 0.0
        dec.l1.weight[0, 0], dec.l1.bias[0] = 10.0, 0.0
        dec.l2.weight[0] = 0.0
        dec.l2.weight[0, 0], dec.l2.bias[0] = 20.0, -7.0
    planes = TriPlanes(32, 8, init_std=0.02).planes.detach()
    planes[:, 0, 12:20, 12:20] = 1.0  # a dense block in the middle
    frame = BoxFrame.from_box(np.array([[-1, -1, -1], [1, 1, 1]], np.float32))
    occ = occupancy_from_planes(planes, dec, frame)
    assert 0.01 < occ.float().mean() < 0.9
    g = torch.Generator().manual_seed(1)
    o = torch.randn(512, 3, generator=g) * 0.3 + torch.tensor([0.0, -3.0, 0.0])
    d = torch.nn.functional.normalize(torch.tensor([0.0, 3.0, 0.0]) + torch.randn(512, 3, generator=g) * 0.3, dim=-1)
    with torch.no_grad():
        full, _, n_full = render_rays(planes, dec, frame, None, o, d)
        skip, _, n_skip = render_rays(planes, dec, frame, occ, o, d)
    assert n_skip < 0.5 * n_full
    assert torch.max(torch.abs(full - skip)) < 1e-2  # only the faint haze of skipped cells differs
    s = march(o, d, frame, occ, jitter=False)
    assert s.unit.abs().max() <= 1.0
