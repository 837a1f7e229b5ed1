"""The print medium's digital payload candidate (`bench.digital_payload`): the embedded source code restores
better the more of its stream arrives and nearly exactly from all of it; a clean snapshot decodes every
layer, bit for bit; a noisy reading keeps only the layers whose CRC holds and never returns wrong bits; the
snapshot keeps the print host fidelity; the print codec's carriers are unchanged by the refactor that lets
both write any values (`embed_values`, `read_carriers`)."""
import numpy as np
import pytest

from snapshot3d.bench import digital_payload as dp
from snapshot3d.codecs import print_carriers, print_embed, print_read, print_source
from snapshot3d.paths import asset
from snapshot3d.scanner.backgrounds import load_host
from snapshot3d.scene import load_scene_file


def _rmse(a, b):
    return float(np.sqrt(np.mean((a - b) ** 2)))


@pytest.fixture(scope="module")
def scene():
    return load_scene_file(asset("spot-print.s3d"))


@pytest.fixture(scope="module")
def snapshot(scene):
    host = load_host("builtin:chelsea")
    return host, dp.embed_digital(host, scene.planes())


def test_source_code_is_embedded(scene):
    planes = scene.planes()
    stream = dp.encode_source(planes)
    assert stream.size == planes.size * dp.INDEX_BITS and set(np.unique(stream)) <= {0, 1}
    errors = [_rmse(dp.decode_source(stream[:n], 16, 4), planes) for n in (0, 200, 1000, 4000, 12000, stream.size)]
    assert all(b < a for a, b in zip(errors, errors[1:])), errors   # more bits, closer
    assert errors[0] == pytest.approx(_rmse(0 * planes, planes), rel=1e-6)   # nothing arrived: the prior's mean
    assert errors[-1] < 0.03                                               # 8-bit indices of every coefficient


def test_clean_snapshot_decodes_every_layer(scene, snapshot):
    host, snap = snapshot
    host8 = np.round(host * 255) / 255
    assert 10 * np.log10(1 / np.mean((snap / 255 - host8) ** 2)) == pytest.approx(print_source.HOST_PSNR, abs=0.1)
    sizes = dp.layer_sizes(dp.DESIGN)
    planes, rd = dp.read_digital(snap, 16, 4, sent=dp.sent_bits(scene.planes()))
    assert rd.layers == len(sizes) and rd.bits == sum(s[2] for s in sizes)
    want = dp.decode_source(dp.encode_source(scene.planes())[:rd.bits], 16, 4)
    np.testing.assert_allclose(planes, want, atol=1e-6)
    assert rd.mutual_info_bits > 0.5 * dp.DESIGN.carriers


def test_noisy_reading_keeps_only_layers_whose_crc_holds(scene, snapshot, rng):
    _, snap = snapshot
    noisy = np.clip(snap + rng.normal(0, 40.0, snap.shape), 0, 255).astype(np.uint8)   # about -2 dB per carrier
    planes, rd = dp.read_digital(noisy, 16, 4)
    assert 0 < rd.layers < len(dp.layer_sizes(dp.DESIGN))
    want = dp.decode_source(dp.encode_source(scene.planes())[:rd.bits], 16, 4)
    np.testing.assert_allclose(planes, want, atol=1e-6)   # what it kept is right, bit for bit


def test_print_carriers_read_the_same_through_the_general_reader(scene):
    host = load_host("builtin:coffee")
    snap = print_embed.embed(host, scene.planes())
    read, factor = print_read.despread(snap, 16, 4)
    r2, f2 = print_read.read_carriers(snap, print_carriers.print_layout(16, 4))
    np.testing.assert_array_equal(read, r2)
    np.testing.assert_array_equal(factor, f2)
