"""Reading a damaged image writes nothing to stderr and never points file descriptor 2 elsewhere, so that in
a process with many threads (the `serve` server's decode threads) no other thread's stderr line is lost
(`snapshot3d.image_decode`). The libraries do print on these inputs when OpenCV reads them itself: each
test checks that first, so that it can fail."""
import io
import os
import subprocess
import sys
import threading
import time
import zlib

import cv2
import numpy as np
import pytest
from PIL import Image

from snapshot3d.errors import UserError
from snapshot3d.image_decode import decode_image
from snapshot3d.scanner.imageio_safe import read_image_bgr

RNG_IMAGE = np.random.default_rng(0).integers(0, 256, (96, 128, 3), dtype=np.uint8)


def _chunk(kind: bytes, body: bytes) -> bytes:
    return len(body).to_bytes(4, "big") + kind + body + zlib.crc32(kind + body).to_bytes(4, "big")


def _chunks(data: bytes) -> list[list]:
    pos, out = 8, []
    while pos < len(data):
        n = int.from_bytes(data[pos:pos + 4], "big")
        out.append([data[pos + 4:pos + 8], data[pos + 8:pos + 8 + n]])
        pos += 12 + n
    return out


def _png(chunks) -> bytes:
    return b"\x89PNG\r\n\x1a\n" + b"".join(_chunk(k, b) for k, b in chunks)


def noisy_jpeg() -> bytes:
    """Garbage between the scan and the end marker: libjpeg warns "Corrupt JPEG data", the image decodes."""
    data = cv2.imencode(".jpg", RNG_IMAGE)[1].tobytes()
    return data[:-2] + b"\x00\x11\x22\x33" + data[-2:]


def garbled_jpeg() -> bytes:
    """Entropy-coded data overwritten mid-scan (the file is still complete): libjpeg warns, then decodes."""
    data = bytearray(cv2.imencode(".jpg", RNG_IMAGE)[1].tobytes())
    data[len(data) // 2:len(data) // 2 + 40] = b"\x55" * 40
    return bytes(data)


def bad_idat_png() -> bytes:
    """Valid chunks and CRCs, but the IDAT's zlib stream is damaged: "libpng error: IDAT: ..."."""
    chunks = _chunks(cv2.imencode(".png", RNG_IMAGE)[1].tobytes())
    idat = next(c for c in chunks if c[0] == b"IDAT")
    idat[1] = idat[1][:2] + bytes(b ^ 0x5A for b in idat[1][2:40]) + idat[1][40:]
    return _png(chunks)


def short_iccp_png() -> bytes:
    """A valid image with a damaged ancillary chunk: "libpng warning: iCCP: too short", the image decodes."""
    chunks = _chunks(cv2.imencode(".png", RNG_IMAGE)[1].tobytes())
    return _png(chunks[:1] + [[b"iCCP", b"bad\x00\x00" + zlib.compress(b"x" * 200)]] + chunks[1:])


def _opencv_stderr(data: bytes) -> str:
    code = "import sys, cv2, numpy as np; cv2.imdecode(np.frombuffer(sys.stdin.buffer.read(), np.uint8), 1)"
    return subprocess.run([sys.executable, "-c", code], input=data, capture_output=True, timeout=60).stderr.decode()


@pytest.mark.parametrize("make,says", [(noisy_jpeg, "Corrupt JPEG data"), (garbled_jpeg, "Corrupt JPEG data"),
                                       (bad_idat_png, "libpng error"), (short_iccp_png, "libpng warning")])
def test_the_libraries_print_on_these_inputs_and_decode_image_does_not(make, says, capfd):
    data = make()
    assert says in _opencv_stderr(data)
    try:
        decode_image(data)
    except ValueError:
        pass
    assert capfd.readouterr().err == ""


def test_a_corrupt_jpeg_or_png_gives_one_line_and_nothing_printed(tmp_path, capfd):
    cut = tmp_path / "cut.jpg"
    cut.write_bytes(noisy_jpeg()[:2000])
    bad = tmp_path / "bad.png"
    bad.write_bytes(bad_idat_png())
    for path, match in ((cut, "cut.jpg is a corrupt or truncated JPEG"), (bad, "bad.png is a corrupt PNG file")):
        with pytest.raises(UserError, match=match) as e:
            read_image_bgr(path)
        assert "\n" not in str(e.value)
    assert "damaged" in str(e.value)   # names the fault: "its image data is damaged (zlib: ...)"
    noisy = tmp_path / "noisy.jpg"
    noisy.write_bytes(noisy_jpeg())
    assert read_image_bgr(noisy).shape == (96, 128, 3)   # decodes, as before, without a word
    assert capfd.readouterr().err == ""


def test_the_command_line_prints_one_line_for_a_corrupt_png(tmp_path):
    bad = tmp_path / "bad.png"
    bad.write_bytes(bad_idat_png())
    proc = subprocess.run([sys.executable, "-m", "snapshot3d", "scan", str(bad), "-o", str(tmp_path / "out.png")],
                          capture_output=True, text=True, timeout=300)
    err = proc.stderr.strip()
    assert proc.returncode != 0 and len(err.splitlines()) == 1 and "libpng" not in err, err
    assert "bad.png is a corrupt PNG file" in err, err


def test_no_stderr_line_of_another_thread_is_lost_while_images_are_read(capfd):
    """One thread writes numbered lines to fd 2 (as the server's log does) while two others read damaged
    images over and over: every line must arrive, and nothing else. (With stderr pointed at a sink while an
    image was read, most of them were lost.)"""
    inputs = [noisy_jpeg(), garbled_jpeg(), bad_idat_png(), short_iccp_png()]
    stop, lines, reads = threading.Event(), 300, [0, 0]

    def read_images(k):
        while not stop.is_set():
            for data in inputs:
                try:
                    decode_image(data)
                except ValueError:
                    pass
                reads[k] += 1

    readers = [threading.Thread(target=read_images, args=(k,)) for k in range(2)]
    for t in readers:
        t.start()
    try:
        while min(reads) < 4:   # both readers are at work
            time.sleep(0.001)
        for i in range(lines):
            os.write(2, f"line {i}\n".encode())
            if i % 30 == 0:
                print(f"print {i}", file=sys.stderr, flush=True)
            time.sleep(0.001)
    finally:
        stop.set()
        for t in readers:
            t.join()
    err = capfd.readouterr().err.splitlines()
    assert [s for s in err if s.startswith("line ")] == [f"line {i}" for i in range(lines)]
    assert [s for s in err if not s.startswith("line ")] == [f"print {i}" for i in range(0, lines, 30)]
    assert min(reads) > 20   # the images were read all the while


def _jpeg(img, **save) -> bytes:
    buf = io.BytesIO()
    Image.fromarray(img).save(buf, "JPEG", **save)
    return buf.getvalue()


def _png_pil(img, **save) -> bytes:
    buf = io.BytesIO()
    img.save(buf, "PNG", **save)
    return buf.getvalue()


def _same_as_opencv(data: bytes) -> None:
    for unchanged in (False, True):
        want = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED if unchanged else cv2.IMREAD_COLOR)
        got = decode_image(data, unchanged)
        # equal here; one level allowed, since Pillow's and OpenCV's bundled libjpeg builds may differ on
        # another CPU or wheel (a wrong orientation or channel order is off by far more)
        assert got.dtype == want.dtype and got.shape == want.shape, unchanged
        assert int(np.abs(got.astype(np.int64) - want.astype(np.int64)).max(initial=0)) <= 1, unchanged


@pytest.mark.parametrize("orientation", range(1, 9))
def test_jpeg_pixels_and_orientation_as_opencv_gives_them(orientation):
    exif = Image.Exif()
    exif[0x0112] = orientation
    _same_as_opencv(_jpeg(RNG_IMAGE, exif=exif, quality=90))


def test_png_and_other_pixels_as_opencv_gives_them():
    img = Image.fromarray(RNG_IMAGE)
    exif = Image.Exif()
    exif[0x0112] = 6
    cases = [cv2.imencode(".png", RNG_IMAGE)[1].tobytes(),
             cv2.imencode(".png", RNG_IMAGE.astype(np.uint16) * 257)[1].tobytes(),
             cv2.imencode(".png", np.dstack([RNG_IMAGE, RNG_IMAGE[..., :1]]))[1].tobytes(),
             cv2.imencode(".png", RNG_IMAGE[..., 0].astype(np.uint16) * 255)[1].tobytes(),
             _png_pil(img.convert("P", palette=Image.ADAPTIVE, colors=13), transparency=3),
             _png_pil(img.convert("1")), _png_pil(img, interlace=True), _png_pil(img, exif=exif),
             _png_pil(img.convert("L"), icc_profile=b"junk" * 10, dpi=(72, 72)),
             _jpeg(RNG_IMAGE[..., 0]), cv2.imencode(".webp", RNG_IMAGE)[1].tobytes(),
             cv2.imencode(".bmp", RNG_IMAGE)[1].tobytes(), cv2.imencode(".tiff", RNG_IMAGE)[1].tobytes()]
    for data in cases:
        _same_as_opencv(data)


def test_damaged_pngs_print_nothing_and_decode_as_opencv_does(capfd):
    """Chunks damaged with their CRCs made right again (so that the damage reaches libpng): nothing printed;
    what decodes is what OpenCV decodes."""
    rng = np.random.default_rng(1)
    img = Image.fromarray(RNG_IMAGE[:37, :53])
    sources = [cv2.imencode(".png", RNG_IMAGE[:37, :53])[1].tobytes(), _png_pil(img, interlace=True),
               _png_pil(img.convert("P", palette=Image.ADAPTIVE, colors=13), transparency=3)]
    extras = [b"iCCP", b"sRGB", b"gAMA", b"tRNS", b"tEXt", b"zTXt", b"pHYs", b"sBIT", b"bKGD", b"eXIf", b"PLTE"]
    cases = []
    for src in sources:
        for _ in range(60):
            chunks = _chunks(src)
            j = int(rng.integers(0, len(chunks)))
            body, how = bytearray(chunks[j][1]), rng.integers(0, 4)
            if how == 0 and body:
                body[int(rng.integers(0, len(body)))] = int(rng.integers(0, 256))
            elif how == 1:
                body = body[:int(rng.integers(0, len(body) + 1))]
            elif how == 2:
                body += bytes(rng.integers(0, 256, 5).tolist())
            else:
                chunks.insert(int(rng.integers(1, len(chunks))),
                              [extras[int(rng.integers(0, len(extras)))], bytes(rng.integers(0, 256, 9).tolist())])
            if how < 3:
                chunks[j][1] = bytes(body)
            cases.append(_png(chunks))
    got = []
    for data in cases:
        try:
            got.append(decode_image(data))
        except ValueError:
            got.append(None)
    assert capfd.readouterr().err == ""
    decoded = [(g, cv2.imdecode(np.frombuffer(d, np.uint8), cv2.IMREAD_COLOR)) for g, d in zip(got, cases)]
    capfd.readouterr()
    both = [(g, w) for g, w in decoded if g is not None and w is not None]
    assert len(both) > 60 and all(np.array_equal(g, w) for g, w in both)
    refused = sum(g is None for g in got)
    assert 20 < refused < len(cases) - 60, refused
