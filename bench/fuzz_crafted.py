"""The file-based input classes of `snapshot3d bench fuzz` (see `bench.fuzz_inputs`): each class makes
its crafted cases, then seeded mutations, for readers in process and a share of command lines."""
from __future__ import annotations

import io
import json
import zlib

import cv2
import numpy as np

from .fuzz_inputs import Input, jpeg_comment, jpeg_sof, mutate, npy, npz, png_header_only, png_text, s3d, s3d_parts

__all__ = ["CLI", "images", "metadata", "scenes", "warnings_class"]

# command lines per target file kind; {d}: the input's folder, {f}: the input file
CLI = {
    "image": [(["decode", "{f}", "-o", "{d}/out", "--views", "1", "--size", "16"], ("out",)),
              (["scan", "{f}", "-o", "{d}/out.png"], ("out.png",)),
              (["restore", "{f}", "-o", "{d}/out.s3d"], ("out.s3d",)),
              (["sheet", "{f}", "-o", "{d}/out.png"], ("out.png",))],
    "s3d": [(["mesh", "{f}", "-o", "{d}/out.glb", "--res", "16"], ("out.glb",)),
            (["render", "{f}", "-o", "{d}/out", "--views", "1", "--size", "16"], ("out",))],
}


def _both(cls, label, files, reader, name, rng, cli_share: float, kind: str | None = None, extra=None):
    """One reader input, and with probability `cli_share` one command line of the file's kind."""
    out = [Input(cls, label, files, reader=reader, arg=name)]
    kind = kind or ("s3d" if reader == "s3d" else "image")
    if rng.random() < cli_share:
        argv, outputs = CLI[kind][int(rng.integers(0, len(CLI[kind])))]
        out.append(Input(cls, label, files, argv=[a.replace("{f}", "{d}/" + name) for a in argv] + (extra or []),
                         outputs=outputs))
    return out


def _n(base: int, scale: float) -> int:
    return max(1, int(round(base * scale)))


def images(seeds, rng, scale) -> list:
    out = []
    thin = [(3, 40000), (1, 65000), (40000, 3), (65000, 1), (1, 1), (2, 2), (7, 7), (1, 380), (380, 1), (5, 9000)]
    for h, w in thin:
        for ext in (".png", ".jpg"):
            img = np.full((h, w, 3), 200, np.uint8) if ext == ".png" or max(h, w) < 65000 else None
            if img is None:
                continue
            data = cv2.imencode(ext, img)[1].tobytes()
            out += _both("thin_image", f"{w}x{h}{ext}", {"x" + ext: data}, "image", "x" + ext, rng, 0.6)
    for _ in range(_n(60, scale)):  # random thin shapes
        h, w = (int(rng.integers(1, 8)), int(rng.integers(100, 30000)))[:: 1 if rng.random() < 0.5 else -1]
        data = cv2.imencode(".png", rng.integers(0, 256, (h, w, 3), np.uint8))[1].tobytes()
        out += _both("thin_image", f"rand{w}x{h}", {"x.png": data}, "image", "x.png", rng, 0.1)
    huge = [(65535, 65535), (100000, 100000), (0, 10), (10, 0), (2**31 - 1, 1), (1, 2**31 - 1), (30000, 30000),
            (9000, 9000)]
    for w, h in huge:
        out += _both("huge_dims", f"png {w}x{h}", {"x.png": png_header_only(w, h)}, "image", "x.png", rng, 0.5)
        if w < 65536 and h < 65536:
            out += _both("huge_dims", f"jpeg {w}x{h}", {"x.jpg": jpeg_sof(w, h)}, "image", "x.jpg", rng, 0.5)
    from PIL import Image
    for mode, fmt in (("L", "PNG"), ("RGBA", "PNG"), ("I;16", "PNG"), ("P", "PNG"), ("1", "PNG"), ("CMYK", "JPEG"),
                      ("L", "JPEG"), ("RGB", "BMP"), ("RGB", "WEBP"), ("RGB", "TIFF"), ("RGB", "GIF")):
        buf = io.BytesIO()
        img = Image.fromarray(seeds.rgb).convert(mode) if mode != "I;16" else \
            Image.fromarray((seeds.rgb[..., 0].astype(np.uint16) * 257))
        img.save(buf, fmt, **({"progressive": True} if fmt == "JPEG" else {}))
        ext = {"PNG": ".png", "JPEG": ".jpg", "BMP": ".bmp", "WEBP": ".webp", "TIFF": ".tif", "GIF": ".gif"}[fmt]
        out += _both("unusual_format", f"{mode} {fmt}", {"x" + ext: buf.getvalue()}, "image", "x" + ext, rng, 1.0)
    for tag in (b"zTXt", b"iTXt"):  # a metadata chunk that inflates to 200 MB, in a real snapshot
        z = zlib.compressobj(9)
        text = b"".join(z.compress(b"S3D1|" + b"a" * (1 << 20)) for _ in range(200)) + z.flush()
        head = b"snapshot3d\0\0" if tag == b"zTXt" else b"snapshot3d\0\1\0\0\0"
        bomb = seeds.snap_png[:33] + npy_free_chunk(tag, head + text) + seeds.snap_png[33:]
        out += _both("text_bomb", f"{tag.decode()} 200 MB", {"x.png": bomb}, "image", "x.png", rng, 1.0)
        out.append(Input("text_bomb", f"{tag.decode()} 200 MB", {"x.png": bomb}, reader="snapshot", arg="x.png"))
    for depth, colour in ((16, 2), (1, 0), (16, 6), (8, 3), (4, 3), (8, 4), (3, 2), (8, 7)):
        out += _both("huge_dims", f"png depth {depth} colour {colour}",
                     {"x.png": png_header_only(64, 64, depth, colour)}, "image", "x.png", rng, 0.2)
    for _ in range(_n(400, scale)):  # truncated at a random point
        seed, ext = [(seeds.snap_png, ".png"), (seeds.snap_jpg, ".jpg"), (seeds.photo_jpg, ".jpg")][int(rng.integers(0, 3))]
        cut = int(rng.integers(0, len(seed)))
        out += _both("truncated", f"{ext} cut at {cut}", {"x" + ext: seed[:cut]}, "image", "x" + ext, rng, 0.08)
    for _ in range(_n(600, scale)):
        n = int(rng.choice([1, 7, 100, 5000, 100000]))
        ext = [".png", ".jpg", ".s3d", ".bin"][int(rng.integers(0, 4))]
        magic = [b"", b"\x89PNG\r\n\x1a\n", b"\xff\xd8\xff", b"PK\x03\x04", b"GIF89a", b"BM", b"RIFF"][int(rng.integers(0, 7))]
        data = magic + rng.integers(0, 256, n, np.uint8).tobytes()
        out += _both("random_bytes", f"{n} bytes {magic[:4]!r}{ext}", {"x" + ext: data},
                     "s3d" if ext == ".s3d" else "image", "x" + ext, rng, 0.06)
    for ext in (".png", ".jpg", ".jpeg", ".s3d", "", ".PNG", ".webp", ".tif"):
        out += _both("zero_byte", f"empty{ext}", {"x" + ext: b""}, "s3d" if ext == ".s3d" else "image", "x" + ext,
                     rng, 1.0)
    for _ in range(_n(900, scale)):  # bit-flipped valid images
        seed, ext = [(seeds.snap_png, ".png"), (seeds.snap_jpg, ".jpg"), (seeds.photo_jpg, ".jpg")][int(rng.integers(0, 3))]
        out += _both("mutated_image", f"{ext} mutated", {"x" + ext: mutate(seed, rng)}, "image", "x" + ext, rng, 0.04)
    return out


def warnings_class(seeds, rng, scale) -> list:
    """Files that make libjpeg, libpng or OpenCV print warnings (premature end, extraneous bytes, bad CRC
    of an ancillary chunk, a bad iCCP profile), valid otherwise."""
    out, jpg, png = [], seeds.snap_jpg, seeds.snap_png
    eoi = jpg.rfind(b"\xff\xd9")
    cases = {"premature end": jpg[:int(len(jpg) * 0.9)] + b"\xff\xd9",
             "extraneous bytes before marker": jpg[:eoi - 200] + b"\x00\x00\x00" + jpg[eoi - 200:],
             "garbage after EOI": jpg + b"garbage" * 100,
             "corrupt entropy": jpg[:len(jpg) // 2] + bytes(50) + jpg[len(jpg) // 2 + 50:]}
    i = png.find(b"tEXt")
    bad_crc = bytearray(png)
    if i > 0:
        n = int.from_bytes(png[i - 4:i], "big")
        bad_crc[i + 4 + n] ^= 0xFF
    cases["png ancillary bad crc"] = bytes(bad_crc)
    iccp = png[:33] + npy_free_chunk(b"iCCP", b"bogus\x00\x00" + b"x\x9c" + b"\x00" * 20) + png[33:]
    cases["png bad iCCP"] = iccp
    cases["png junk after IEND"] = png + b"junk" * 100
    for label, data in cases.items():
        ext = ".png" if label.startswith("png") else ".jpg"
        for _ in range(_n(6, scale)):
            out += _both("library_warnings", label, {"x" + ext: data}, "image", "x" + ext, rng, 0.5)
    return out


def npy_free_chunk(tag, data):
    from .fuzz_inputs import _chunk
    return _chunk(tag, data)


META_FIELDS = {  # crafted values per metadata field of "S3D1|codec|b=..|o=..|t=..|p=..|s=.."
    "meta_planes": [("p", v) for v in ("100,8", "0,8", "64,-1", "64,9", "64,0", "4,1", "65535,65535", "64,8.5",
                                       "3,8", "64,13", "1e3,8", "64", "64,8,1", "", "-0,8", "0x40,8")],
    "meta_overflow": [(k, v) for k, v in (("p", "inf,8"), ("p", "1e309,8"), ("b", "-1e309,-1,-1,1,1,1"),
                                          ("b", "-inf,-1,-1,1,1,inf"), ("o", "1e309,20,40"), ("o", "4,20,1e309"),
                                          ("s", "1e309"), ("s", "-inf"), ("t", "1e309,0,0"), ("b", "-1e38,-1,-1,1e38,1,1"),
                                          ("o", "1e38,20,40"), ("s", "1e38"), ("v", "99999999999999999999"))],
    "meta_nan": [(k, v) for k, v in (("b", "nan,-1,-1,1,1,1"), ("b", "0,0,0,0,0,0"), ("b", "1,1,1,-1,-1,-1"),
                                     ("o", "0,20,40"), ("o", "-1,20,40"), ("o", "nan,20,40"), ("o", "4,20,0"),
                                     ("o", "4,20,180"), ("o", "4,20,1e9"), ("o", "4,95,40"), ("s", "0"), ("s", "-1"),
                                     ("s", "1e-30"), ("s", "nan"), ("t", "nan,0,0"), ("b", "-1e-30,-1e-30,-1e-30,1e-30,1e-30,1e-30"))],
}


def _edited(meta: str, key: str, value: str) -> str:
    parts = meta.split("|")
    if key == "v":
        return "S3D" + value + "|" + "|".join(parts[1:])
    kept = [p for p in parts if not p.startswith(key + "=")]
    return "|".join(kept + [f"{key}={value}"])


def metadata(seeds, rng, scale) -> list:
    """Edited metadata in its three carriers (PNG text, JPEG comment, the QR text given to --meta), on the
    real snapshot's pixels (its mark disagrees) and on pixels with no mark (the text is trusted)."""
    out = []
    codecs = ["hinet-3", "hinet-1", "print-2", "print-1", "nope", "", "x" * 600]
    for cls, edits in META_FIELDS.items():
        for key, value in edits:
            full = codecs[int(rng.integers(0, 4))]
            for codec in codecs:
                text = _edited(seeds.meta.replace("hinet-3", codec), key, value)
                out.append(Input(cls, f"text {codec[:10]} {key}={value}", reader="meta", arg=text))
                if codec != full:
                    continue
                for pixels in ("snapshot", "noise"):
                    rgb = seeds.rgb if pixels == "snapshot" else seeds.noise
                    out += _both(cls, f"png {codec} {key}={value} on {pixels}", {"x.png": png_text(rgb, text)},
                                 "snapshot", "x.png", rng, 0.15)
                    out += _both(cls, f"jpg {codec} {key}={value} on {pixels}", {"x.jpg": jpeg_comment(rgb, text)},
                                 "image", "x.jpg", rng, 0.1)
                out.append(Input(cls, f"qr {codec} {key}={value}", {"x.png": seeds.snap_png}, reader="snapshot",
                                 arg="x.png|" + text))
                for other in codecs[:4]:
                    out.append(Input(cls, f"qr {other} {key}={value}", {"x.png": seeds.snap_png},
                                     argv=["restore", "{d}/x.png", "-o", "{d}/out.s3d", "--meta",
                                           text.replace(codec, other, 1) if codec else text], outputs=("out.s3d",)))
    for i in range(_n(3000, scale)):  # mutated text: every one parsed, one in 20 in its carriers
        text = mutate(seeds.meta.encode(), rng, int(rng.integers(1, 5))).decode("latin-1")
        out.append(Input("meta_mutated", "text mutated", reader="meta", arg=text))
        if i % 20 == 0:
            out += _both("meta_mutated", "png text mutated", {"x.png": png_text(seeds.noise, text)}, "snapshot",
                         "x.png", rng, 0.3)
    for codec in codecs[4:]:
        out += _both("meta_planes", f"codec {codec[:10]!r}", {"x.png": png_text(seeds.noise, seeds.meta.replace("hinet-3", codec))},
                     "snapshot", "x.png", rng, 0.5)
    return out


def scenes(seeds, rng, scale) -> list:
    parts, out = s3d_parts(seeds.s3d), []
    header = json.loads(bytes(parts["header"]).decode())

    def add(cls, label, data, share=0.3):
        out.extend(_both(cls, label, {"x.s3d": data}, "s3d", "x.s3d", rng, share))
    for h in ([], "text", None, 1, [1, 2], {"format_version": None}, {}, {"format_version": "1"}):
        add("s3d_header", f"header {json.dumps(h)[:30]}", s3d(parts, h))
    for orbit in ([4, 20, 40], None, "far", 4.2, {"radius": "4"}, {"radius": [4]}, {"radius": True}, {},
                  {"radius": 4, "target": "x"}, {"radius": 4, "target": [1, 2]}, {"radius": 4, "fov_deg": None}):
        add("s3d_header", f"orbit {json.dumps(orbit)[:30]}", s3d(parts, dict(header, orbit=orbit)))
    for k, v in (("name", 5), ("meta", []), ("meta", "x"), ("decoder_version", 3), ("decoder_version", "x" * 10000)):
        add("s3d_header", f"{k}={json.dumps(v)[:20]}", s3d(parts, dict(header, **{k: v})))
    for raw in (b"{", b"\xff\xfe", b"", b"[" * 5000 + b"]" * 5000, b'{"a": 1e999}', b"NaN"):
        add("s3d_header", f"raw header {raw[:10]!r}", s3d(parts, raw))
    good = s3d(parts)
    i = good.find(b"\x93NUMPY")
    for j in range(8):
        flipped = bytearray(good)
        flipped[i + 10 + int(rng.integers(0, 60))] = int(rng.choice([ord("("), ord("'"), ord("{"), 0, ord("\n")]))
        add("s3d_npload", f"npy header byte {j}", bytes(flipped))
    v = bytearray(good)
    for k in range(len(v) - 4):  # zip "version needed" of every local and central header -> 9.9
        if v[k:k + 4] in (b"PK\x03\x04",):
            v[k + 4:k + 6] = (99).to_bytes(2, "little")
        if v[k:k + 4] == b"PK\x01\x02":
            v[k + 6:k + 8] = (99).to_bytes(2, "little")
    add("s3d_npload", "zip version 9.9", bytes(v))
    for shape, descr in (((3, 8, 300000, 300000), "|u1"), ((3, 12, 4096, 4096), "|u1"), ((3, 4, 0, 0), "|u1"),
                         ((3, 8, 64, 64), "<f8"), ((3, 8, 64, 64), "|O"), ((-1, 8, 64, 64), "|u1"),
                         ((3, 8, 64), "|u1"), ((2**40,), "|u1")):
        add("s3d_bomb" if np.prod(np.abs(shape), dtype=float) > 1e7 or 0 in shape else "s3d_npload",
            f"codes {descr} {shape}", s3d(parts, codes=npy(descr, shape, b"\0" * 1024)))
    zeros = np.zeros((3, 12, 1024, 1024), np.uint8)
    add("s3d_bomb", "deflate bomb codes 3x12x1024x1024",
        npz({"codes": npy(zeros), "box": npy(parts["box"]), "header": npy(parts["header"])}, compress=True))
    add("s3d_bomb", "header text 50 MB", s3d(parts, header=b'{"x": "' + b"a" * 50_000_000 + b'"}'), 0.0)
    for box in ([[np.nan] * 3, [1] * 3], [[-np.inf] * 3, [np.inf] * 3], [[1] * 3, [-1] * 3], [[0] * 3, [0] * 3],
                [[-1e30] * 3, [1e30] * 3], [[-1, -1, -1], [1, 1, 1e-9]]):
        add("nonfinite_numbers", f"box {box}", s3d(parts, box=np.array(box, np.float32)))
    for o in ({"radius": 0}, {"radius": -1}, {"radius": float("nan")}, {"radius": 1e30}, {"fov_deg": 0},
              {"fov_deg": 180}, {"fov_deg": 1e9}, {"elevation_deg": float("nan")}, {"elevation_deg": 90},
              {"target": [float("inf"), 0, 0]}):
        add("nonfinite_numbers", f"orbit {o}", s3d(parts, dict(header, orbit=dict(header["orbit"], **o))), 0.6)
    for _ in range(_n(2500, scale)):
        add("mutated_s3d", "s3d mutated", mutate(seeds.s3d, rng), 0.004)
    for _ in range(_n(500, scale)):
        cut = int(rng.integers(0, len(seeds.s3d)))
        add("truncated", f"s3d cut at {cut}", seeds.s3d[:cut], 0.05)
    return out
