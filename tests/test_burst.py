"""Several photos of one printed sheet (`decode P1 P2 ...`, `viewer.burst`): the pilots' weights, the combined
capture, refusals of photos that are not of one print, and the simulator's print seed that makes such photos."""
from dataclasses import replace
from importlib import resources
from pathlib import Path

import cv2
import numpy as np
import pytest
from helpers import assert_one_line_error
from test_decode import run_blocked
from test_serve_page import _page, base_url, browser  # noqa: F401 (fixtures)

from snapshot3d import formats
from snapshot3d.errors import UserError

SCENE = Path(str(resources.files("snapshot3d") / "assets" / "spot-print.s3d"))
PRINT = 7   # the print seed of the coffee sheet's photos


def test_independent_noise_weighs_each_photo_by_its_gain_over_its_noise():
    from snapshot3d.viewer.burst import pilot_weights
    w = pilot_weights([0.6, 0.6, 0.3], [0.001, 0.002, 0.001])
    assert w == pytest.approx([0.5, 0.25, 0.25])
    assert pilot_weights([0.5], [0.01]) == pytest.approx([1.0])
    for gains, noises in (([0.5, 0.0], [0.1, 0.1]), ([0.5, 0.5], [0.1, np.inf]), ([0.5], [0.1, 0.1]), ([], [])):
        with pytest.raises(ValueError):
            pilot_weights(gains, noises)


def test_the_pilots_residuals_weigh_photos_as_the_best_unbiased_estimate(rng):
    """Independent noise: the maximal-ratio weights. A noise the print puts in every photo: the weights lean on the
    photo with the least noise of its own, where g / n would spread them."""
    from snapshot3d.viewer.burst import blue_weights, pilot_weights
    p = 20000
    own = rng.normal(0, 1, (3, p)) * np.array([[0.01], [0.02], [0.02]])
    gains = np.array([0.5, 0.5, 0.25])
    w = blue_weights(gains, own)   # residuals are in the readings' units divided by the gain
    want = pilot_weights(gains, (own.std(1) * gains) ** 2)
    assert w == pytest.approx(want, abs=0.01)
    common = rng.normal(0, 0.05, p)
    w2 = blue_weights(gains, own + common)
    ind = pilot_weights(gains, ((own + common).std(1) * gains) ** 2)
    a = w2 * gains / np.sum(w2 * gains)   # the weights on the readings divided by their gains
    assert a[0] > 0.6 and ind[0] * gains[0] / np.sum(ind * gains) < 0.45
    assert blue_weights([0.5], own[:1]) == pytest.approx([1.0])
    dead = own.copy()
    dead[1] = np.inf   # a photo whose pilots read nothing weighs 0; the others as without it
    assert blue_weights([0.5, -0.01, 0.25], dead) == pytest.approx(np.insert(blue_weights(gains[[0, 2]], own[[0, 2]]),
                                                                               1, 0.0))
    for gains_, res in (([0.0, -1.0], own[:2]), ([0.5, 0.5], np.full((2, 3), np.nan)), ([0.5], own[:2])):
        with pytest.raises(ValueError):
            blue_weights(gains_, res)


def test_captures_combine_as_their_weighted_mean_rounded(rng):
    from snapshot3d.viewer.burst import combine_captures
    a, b = (rng.integers(0, 256, (8, 8, 3)).astype(np.uint8) for _ in range(2))
    assert np.array_equal(combine_captures(np.stack([a, b]), [1.0, 0.0]), a)
    got = combine_captures(np.stack([a, b]), [0.25, 0.75])
    assert got.dtype == np.uint8 and np.abs(got - (0.25 * a + 0.75 * b)).max() <= 0.5 + 1e-9
    with pytest.raises(ValueError):
        combine_captures(np.stack([a, b]), [1.0])


def test_detail_match_ignores_light_and_tells_pictures_apart(rng):
    from snapshot3d.viewer.burst import MIN_MATCH, detail_match
    pic = cv2.GaussianBlur(rng.integers(0, 256, (380, 380, 3)).astype(np.uint8), (0, 0), 2)
    ramp = np.linspace(0.6, 1.0, 380)[None, :, None]   # a light gradient and a colour cast
    lit = np.clip(pic * ramp * np.array([1.0, 0.9, 0.8]) + 10, 0, 255).astype(np.uint8)
    other = cv2.GaussianBlur(rng.integers(0, 256, (380, 380, 3)).astype(np.uint8), (0, 0), 2)
    assert detail_match(pic, lit) > 0.9
    assert abs(detail_match(pic, other)) < MIN_MATCH / 3


def _sheet(host: str):
    from snapshot3d.codecs import print_embed
    from snapshot3d.scanner.backgrounds import load_host
    from snapshot3d.scanner.qr import scene_meta
    from snapshot3d.scanner.sheet import render_sheet
    from snapshot3d.scene import load_scene_file
    scene = load_scene_file(SCENE)
    return render_sheet(print_embed.embed(load_host(f"builtin:{host}"), scene.planes()),
                        scene_meta(scene, formats.PRINT_CODEC, 1.0), 2), scene


@pytest.fixture(scope="module")
def photos(tmp_path_factory):
    """Three `moderate` photos of one print of spot in coffee, one of a print of it in chelsea, and one of the coffee
    print with ink over its QR code (JPEG files)."""
    from snapshot3d.scanner.simulate import simulate
    root = tmp_path_factory.mktemp("burst")
    (coffee, scene), (chelsea, _) = _sheet("coffee"), _sheet("chelsea")
    inked = coffee.copy()
    x0, y0, x1, y1 = formats.QR_BOX
    sx0, sy0 = formats.SHEET_BOX[:2]
    inked[(y0 - sy0) * 2:(y1 - sy0) * 2, (x0 - sx0) * 2:(x1 - sx0) * 2] = 0
    paths = []
    for name, sheet, seed, pseed in (("a.jpg", coffee, 0, PRINT), ("b.jpg", coffee, 1, PRINT),
                                     ("c.jpg", coffee, 2, PRINT), ("cat.jpg", chelsea, 0, PRINT),
                                     ("inked.jpg", inked, 3, PRINT)):
        (root / name).write_bytes(simulate(sheet, "moderate", seed, print_seed=pseed)[0])
        paths.append(root / name)
    return paths, scene


def test_three_photos_of_one_print_restore_better_than_one(photos):
    from snapshot3d.viewer.decode import decode_scene
    paths, scene = photos
    truth = scene.planes()

    def err(ds):
        return float(np.sqrt(np.mean((ds.planes - truth) ** 2)))
    singles = [err(decode_scene(p, estimate=False)) for p in paths[:3]]
    ds = decode_scene(paths[:3], estimate=False)
    assert err(ds) < np.median(singles) and err(ds) < 1.02 * min(singles), (err(ds), singles)
    got = ds.report["photos"]
    assert [p["photo"] for p in got] == ["a.jpg", "b.jpg", "c.jpg"]
    assert sum(p["weight"] for p in got) == pytest.approx(1.0, abs=2e-4)
    assert got[int(np.argmin(singles))]["weight"] == max(p["weight"] for p in got)   # the best photo leads
    assert ds.report["source"] == "3 photos of a sheet, combined"


def test_a_photo_whose_qr_code_is_unread_joins_one_that_read_it(photos, tmp_path):
    """The QR code (scene box, plane size, codec) is read once for all; a photo that missed it still counts."""
    from snapshot3d.viewer.decode import decode_scene, read_photos
    paths, _ = photos
    ds = decode_scene([paths[4], paths[0]], estimate=False)
    got = {p["photo"]: p for p in ds.report["photos"]}
    assert got["inked.jpg"]["qr_read"] is False and got["a.jpg"]["qr_read"] is True
    assert got["inked.jpg"]["weight"] > 0.05
    with pytest.raises(UserError, match="could not read its QR code"):
        read_photos([paths[4], _reencoded(paths[4], tmp_path)])


def _reencoded(path: Path, folder: Path) -> Path:
    """The photo at `path` saved again as JPEG in `folder`: the same picture in other bytes."""
    out = folder / f"again-{path.name}"
    cv2.imwrite(str(out), cv2.imread(str(path)), [cv2.IMWRITE_JPEG_QUALITY, 97])
    return out


def test_decode_combines_photos_without_torch(photos, tmp_path):
    import shutil
    paths, _ = photos
    burst = tmp_path / "burst"   # a folder of photos, as a phone's burst is copied
    burst.mkdir()
    for p in paths[:2]:
        shutil.copy(p, burst / p.name)
    (burst / "notes.txt").write_text("not a photo")
    proc = run_blocked("decode", str(burst), "-o", str(tmp_path / "out"), "--views", "2", "--size", "48")
    assert proc.returncode == 0, proc.stderr
    assert "a.jpg: weight" in proc.stdout and "b.jpg: weight" in proc.stdout
    assert (tmp_path / "out" / "views" / "001.png").is_file()
    (tmp_path / "empty").mkdir()
    assert_one_line_error(run_blocked("decode", str(tmp_path / "empty"), "-o", str(tmp_path / "out2")),
                          "is a folder with no .jpg or .png photo in it")
    assert not (tmp_path / "out2").exists()


def test_photos_of_another_print_or_a_snapshot_file_are_refused(photos, tmp_path):
    from snapshot3d.viewer.decode import read_photos
    paths, _ = photos
    with pytest.raises(UserError, match=r"cat\.jpg shows another print than a\.jpg"):
        read_photos([paths[0], paths[3]])
    with pytest.raises(UserError, match=r"give 1 to 8 photos"):
        read_photos([paths[0]] * 9)
    with pytest.raises(UserError, match=r"^missing\.jpg: "):
        read_photos([tmp_path / "missing.jpg", paths[0]])
    copy = tmp_path / "a-copy.jpg"   # one photo twice, or under two names, is refused before any scan
    copy.write_bytes(paths[0].read_bytes())
    with pytest.raises(UserError, match=r"^a\.jpg is given twice: give different photos"):
        read_photos([paths[0], paths[1], paths[0]])
    with pytest.raises(UserError, match=r"^a-copy\.jpg is a copy of a\.jpg"):
        read_photos([paths[0], copy])
    snap = tmp_path / "snap.png"
    proc = run_blocked("decode", str(paths[0]), str(paths[3]), "-o", str(tmp_path / "out"))
    assert_one_line_error(proc, "cat.jpg shows another print")
    assert not (tmp_path / "out").exists()
    from snapshot3d.scanner.qr import scene_meta
    from snapshot3d.scanner.scan import scan_file
    from snapshot3d.scanner.snapfile import write_snapshot
    write_snapshot(snap, scan_file(paths[0]).snapshot, scene_meta(photos[1], formats.PRINT_CODEC, 1.0))
    with pytest.raises(UserError, match=r"snap\.png is a snapshot file: only photos of one printed sheet"):
        read_photos([paths[0], snap])


def test_a_print_seed_keeps_the_print_and_changes_the_photo(monkeypatch):
    from snapshot3d.scanner import simulate as sim
    from snapshot3d.scanner.presets import get_preset
    printed, real = [], sim.print_sheet
    monkeypatch.setattr(sim, "print_sheet", lambda *a: printed.append(real(*a)) or printed[-1])
    sheet, _ = _sheet("coffee")
    small = replace(get_preset("moderate"), frame=(640, 480), coverage=(0.3, 0.5))
    a, b, c = (sim.simulate(sheet, small, s, print_seed=p)[0] for s, p in ((0, 3), (1, 3), (0, 4)))
    assert np.array_equal(printed[0], printed[1]) and not np.array_equal(printed[0], printed[2])
    assert a != b
    assert sim.simulate(sheet, small, 0)[2]["print_seed"] is None   # one print per photo, as before


def test_the_server_combines_several_uploads_and_refuses_another_print(photos, tmp_path):
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        from fastapi.testclient import TestClient

    from snapshot3d.viewer.serve_config import ServeConfig
    from snapshot3d.viewer.server import create_app
    paths, _ = photos
    client = TestClient(create_app(ServeConfig(cache=str(tmp_path / "cache"))))

    def post(*ps):
        return client.post("/v1/decode", files=[("file", (p.name, p.read_bytes())) for p in ps])
    r = post(paths[0], paths[1])
    assert r.status_code == 200, r.text
    assert [p["photo"] for p in r.json()["report"]["photos"]] == ["a.jpg", "b.jpg"]
    for bad, match in (((paths[0], paths[3]), "cat.jpg shows another print"), ((paths[0],) * 9, "give 1 to 8")):
        r = post(*bad)
        assert r.status_code == 422 and match in r.json()["error"], r.text
    cache = tmp_path / "cache"
    assert len([p for p in cache.iterdir() if not p.name.startswith(".")]) == 1   # the one scene decoded
    assert not any(list(p.iterdir()) for p in cache.glob(".uploads.*"))   # no upload left behind


def test_the_page_sends_several_photos_of_one_print(photos, browser, base_url):  # noqa: F811 (the imported fixtures)
    paths, _ = photos
    page, errors = _page(browser, base_url)
    page.set_input_files("#photo", [str(p) for p in paths[:2]])
    page.wait_for_function("window.snapshot3d.ready || window.snapshot3d.error", timeout=60000)
    assert page.evaluate("snapshot3d.error") is None and not errors, errors
    assert "2 photos of a sheet, combined" in page.inner_text("#status")


def test_a_poor_estimate_suggests_several_photos():
    from snapshot3d.viewer.commands import POOR_DB, _quality_lines
    q = {"restore_psnr_expected_db": POOR_DB - 1, "basis": "the pilots", "calibration": {"held_out_rmse_db": 1.3}}
    lines = _quality_lines(q)
    assert len(lines) == 2 and "several photos of the print decode better together" in lines[1]
    assert len(_quality_lines(dict(q, restore_psnr_expected_db=POOR_DB + 1))) == 1
