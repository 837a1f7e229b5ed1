"""The print sheet: layout constants, markers that identify the format, the QR payload, PNG and PDF output."""
import subprocess
import sys

import cv2
import numpy as np
import pytest

from snapshot3d import formats
from snapshot3d.codecs.media import MEDIA
from snapshot3d.scanner import layout
from snapshot3d.scanner.detect import detect_markers
from snapshot3d.scanner.pdf import pdf_image
from snapshot3d.scanner.qr import SheetMeta, decode_payload, encode_payload, read_qr
from snapshot3d.scanner.sheet import render_sheet


def _snapshot():
    rng = np.random.default_rng(1)
    return (rng.random((formats.SNAPSHOT_SIZE, formats.SNAPSHOT_SIZE, 3)) * 255).astype(np.uint8)


def test_layout_is_consistent():
    w, h = layout.sheet_size()
    x0, y0, x1, y1 = formats.SHEET_BOX
    n = formats.SNAPSHOT_SIZE
    # everything inside the sheet, the quiet zone around it, nothing overlapping the snapshot
    boxes = [formats.PATCH_BOX, formats.QR_BOX, *formats.HEAD_CODE_BOXES] + [(q[0, 0], q[0, 1], q[2, 0], q[2, 1])
                                                                           for q in layout.marker_corners().values()]
    for bx0, by0, bx1, by1 in boxes:
        assert x0 < bx0 < bx1 < x1 and y0 < by0 < by1 < y1
        assert bx1 <= 0 or bx0 >= n  # left or right of the snapshot
    for i, a in enumerate(boxes):   # at least 6 units between any two (the scanner's crops take 4 round a code)
        for b in boxes[i + 1:]:
            assert a[2] + 6 <= b[0] or b[2] + 6 <= a[0] or a[3] + 6 <= b[1] or b[3] + 6 <= a[1], (a, b)
    assert formats.SNAPSHOT_SIZE == 380 and len(formats.PATCH_COLOURS) == formats.PATCH_ROWS * formats.PATCH_COLS
    assert h / n < 1.11  # thin top and bottom margins: the snapshot can fill ~60% of a 4:3 frame


def test_sheet_pixels_markers_and_qr():
    snap = _snapshot()
    meta = SheetMeta(box=(-1.5, -1, -0.5, 1.5, 1, 0.5), orbit=(3.25, 20, 40))
    k = 2
    sheet = render_sheet(snap, meta, k)
    w, h = layout.sheet_size()
    assert sheet.shape == (h * k, w * k, 3) and sheet.dtype == np.uint8
    x0, y0 = formats.SHEET_BOX[:2]
    block = sheet[-y0 * k:(-y0 + formats.SNAPSHOT_SIZE) * k, -x0 * k:(-x0 + formats.SNAPSHOT_SIZE) * k]
    np.testing.assert_array_equal(block[::k, ::k], snap)  # each snapshot pixel printed as a k x k block
    ids, corners = detect_markers(cv2.cvtColor(sheet, cv2.COLOR_RGB2BGR))
    assert sorted(ids.tolist()) == list(formats.SHEET_MARKER_IDS[1])
    to_px = layout.layout_to_pixels(k)
    for i, c in zip(ids, corners):
        expected = layout.marker_corners()[int(i)] @ to_px[:2, :2].T + to_px[:2, 2]
        assert np.abs(c - expected).max() < 0.6  # ArUco's corners lie on the border pixels' centres
    qx0, qy0, qx1, qy1 = formats.QR_BOX
    crop = cv2.cvtColor(sheet[(qy0 - y0 - 6) * k:(qy1 - y0 + 6) * k, (qx0 - x0 - 6) * k:(qx1 - x0 + 6) * k],
                        cv2.COLOR_RGB2GRAY)
    text = read_qr(cv2.resize(crop, None, fx=2, fy=2, interpolation=cv2.INTER_NEAREST))
    assert text == encode_payload(meta)
    back = decode_payload(text)
    assert back.codec == MEDIA[formats.DEFAULT_MEDIUM].codec and back.version == formats.SHEET_FORMAT_VERSION
    np.testing.assert_allclose(back.box, meta.box) and np.testing.assert_allclose(back.orbit, meta.orbit)


def test_payload_round_trip_with_codec_fields():
    meta = SheetMeta(box=(-1, -0.5, -1, 1, 0.5, 1), orbit=(3.2, 20, 40), target=(0.1, 0, -0.2), planes=(48, 4),
                     strength=1.5)
    back = decode_payload(encode_payload(meta))
    assert back.planes == (48, 4) and back.strength == 1.5
    np.testing.assert_allclose(back.target, meta.target) and np.testing.assert_allclose(back.box, meta.box)
    for bad in ("S3D1|hinet-1|p=64", "S3D1|hinet-1|s=x", "S3D1|hinet-1|t=1,2"):
        with pytest.raises(ValueError, match="malformed"):
            decode_payload(bad)


def test_payload_rejects_foreign_text():
    with pytest.raises(ValueError):
        decode_payload("https://example.com")
    assert decode_payload("S3D1|none").box is None


def test_sheet_cli_png_pdf(tmp_path):
    snap = tmp_path / "snap.png"
    cv2.imwrite(str(snap), _snapshot())
    for name, width, dpi in (("s.png", 100, 300), ("p.pdf", 150, 300)):
        proc = subprocess.run([sys.executable, "-m", "snapshot3d", "sheet", str(snap), "-o", str(tmp_path / name),
                               "--width-mm", str(width), "--dpi", str(dpi)], capture_output=True, text=True)
        assert proc.returncode == 0, proc.stderr
    png = cv2.imread(str(tmp_path / "s.png"))
    assert png.shape[1] == layout.sheet_size()[0] * round(100 / 25.4 * 300 / layout.sheet_size()[0])
    pdf = (tmp_path / "p.pdf").read_bytes()
    assert pdf.startswith(b"%PDF")
    # page width in points (1/72 inch) = 150 mm
    media = pdf[pdf.index(b"/MediaBox"):][:80].split(b"[")[1].split(b"]")[0].split()
    assert abs(float(media[2]) / 72 * 25.4 - 150) < 0.5
    # the PDF holds the page losslessly, and the same page is written beside it as PNG (what simulate reads)
    beside = cv2.cvtColor(cv2.imread(str(tmp_path / "p.png")), cv2.COLOR_BGR2RGB)
    assert np.array_equal(pdf_image(pdf), beside)
    assert beside.shape[1] == layout.sheet_size()[0] * round(150 / 25.4 * 300 / layout.sheet_size()[0])
    big = tmp_path / "snap4x.png"                        # a file-medium snapshot is written at 4x: the same sheet
    cv2.imwrite(str(big), np.repeat(np.repeat(_snapshot(), 4, 0), 4, 1))
    proc = subprocess.run([sys.executable, "-m", "snapshot3d", "sheet", str(big), "-o", str(tmp_path / "s4.png"),
                           "--width-mm", "100", "--dpi", "300"], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    assert np.array_equal(cv2.imread(str(tmp_path / "s4.png")), png)
    bad = tmp_path / "small.png"
    cv2.imwrite(str(bad), np.zeros((100, 120, 3), np.uint8))
    proc = subprocess.run([sys.executable, "-m", "snapshot3d", "sheet", str(bad), "-o", str(tmp_path / "x.png")],
                          capture_output=True, text=True)
    assert proc.returncode == 1 and "380x380" in proc.stderr and not (tmp_path / "x.png").exists()
