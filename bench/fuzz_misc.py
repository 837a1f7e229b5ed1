"""More input classes of `snapshot3d bench fuzz`: wrong extensions, unicode and odd paths, option values,
and nerfstudio transforms.json (the fit's reader, called in process)."""
from __future__ import annotations

import json

import cv2
import numpy as np

from .fuzz_inputs import Input, mutate

__all__ = ["misc"]


def wrong_extensions(seeds, rng) -> list:
    out = []
    swaps = [(seeds.snap_png, "x.jpg"), (seeds.snap_jpg, "x.png"), (seeds.s3d, "x.png"), (seeds.snap_png, "x.s3d"),
             (seeds.snap_png, "x.txt"), (seeds.snap_png, "x"), (seeds.photo_jpg, "x.s3d"), (seeds.s3d, "x.jpg")]
    for data, name in swaps:
        reader = "s3d" if name.endswith(".s3d") else "image"
        out.append(Input("wrong_extension", f"{name} holding {data[:4]!r}", {name: data}, reader=reader, arg=name))
        for argv, outs in ((["decode", "{d}/" + name, "-o", "{d}/out", "--views", "1", "--size", "16"], ("out",)),
                           (["restore", "{d}/" + name, "-o", "{d}/out.s3d"], ("out.s3d",)),
                           (["mesh", "{d}/" + name, "-o", "{d}/out.glb", "--res", "16"], ("out.glb",))):
            out.append(Input("wrong_extension", f"{argv[0]} {name}", {name: data}, argv=argv, outputs=outs))
    for out_name, cmd in (("out.jpg", "restore"), ("out.s3d", "scan"), ("out.txt", "sheet"), ("out.png", "mesh"),
                          ("out.s3d.", "restore"), ("OUT.S3D", "restore")):
        src = "x.s3d" if cmd == "mesh" else "x.png"
        data = seeds.s3d if cmd == "mesh" else seeds.snap_png
        out.append(Input("wrong_extension", f"{cmd} -o {out_name}", {src: data},
                         argv=[cmd, "{d}/" + src, "-o", "{d}/" + out_name], outputs=(out_name,)))
    return out


def odd_paths(seeds) -> list:
    out = []
    for name in ("snap ☃.png", "名前.png", "a\nb.png", "é" * 60 + ".png", "-o.png", " .png", "x" * 250 + ".png",
                 "a\tb.png", "%s%n.png", "$(id).png", "a\rb.png"):
        out.append(Input("odd_path", f"input {name!r}"[:40], {name: seeds.snap_png}, reader="image", arg=name))
        out.append(Input("odd_path", f"restore {name!r}"[:40], {name: seeds.snap_png},
                         argv=["restore", "{d}/" + name, "-o", "{d}/out.s3d"], outputs=("out.s3d",)))
    for target in ("{d}/missing/dir/out.s3d", "{d}", "{d}/x.png", "/proc/out.s3d", "{d}/" + "y" * 300 + ".s3d",
                   "{d}/a\nb.s3d", "/dev/null"):
        out.append(Input("odd_path", f"restore -o {target[:30]!r}", {"x.png": seeds.snap_png},
                         argv=["restore", "{d}/x.png", "-o", target], outputs=()))
    for missing in ("{d}/nope.png", "{d}", "/dev/zero", "/proc/self/mem", "/etc"):
        out.append(Input("odd_path", f"decode {missing}", {}, argv=["decode", missing, "-o", "{d}/out", "--views", "1",
                                                                     "--size", "16"], outputs=("out",)))
    return out


def option_values(seeds) -> list:
    out = []
    bad = ["nan", "inf", "-inf", "-1", "0", "1e9", "abc", "", "1e309", "99999999999999999999", "0.5", "-0"]
    for v in bad:
        for argv, outs, src in (
                (["decode", "{d}/x.png", "-o", "{d}/out", "--views", "1", "--size", v], ("out",), "png"),
                (["decode", "{d}/x.png", "-o", "{d}/out", "--views", v, "--size", "16"], ("out",), "png"),
                (["decode", "{d}/x.png", "-o", "{d}/out", "--views", "1", "--size", "16", "--samples", v], ("out",), "png"),
                (["mesh", "{d}/x.s3d", "-o", "{d}/out.glb", "--res", v], ("out.glb",), "s3d"),
                (["render", "{d}/x.s3d", "-o", "{d}/out", "--views", "1", "--size", v], ("out",), "s3d"),
                (["sheet", "{d}/x.png", "-o", "{d}/out.png", "--width-mm", v], ("out.png",), "png"),
                (["sheet", "{d}/x.png", "-o", "{d}/out.png", "--dpi", v], ("out.png",), "png")):
            files = {"x.s3d": seeds.s3d} if src == "s3d" else {"x.png": seeds.snap_png}
            out.append(Input("option_values", " ".join(a for a in argv if "{d}" not in a)[:50], files, argv=argv,
                             outputs=outs))
    for v in ("nan", "-1", "1e30", "abc"):
        out.append(Input("option_values", f"simulate --seed {v}", {"x.png": seeds.snap_png},
                         argv=["simulate", "{d}/x.png", "-o", "{d}/out.jpg", "--seed", v], outputs=("out.jpg",)))
    out.append(Input("option_values", "simulate --severity bad", {"x.png": seeds.snap_png},
                     argv=["simulate", "{d}/x.png", "-o", "{d}/out.jpg", "--severity", "bad"], outputs=("out.jpg",)))
    return out


def transforms(seeds, rng, n: int) -> list:
    img = cv2.imencode(".png", np.full((24, 32, 3), 128, np.uint8))[1].tobytes()
    eye = np.eye(4).tolist()
    base = {"fl_x": 30.0, "fl_y": 30.0, "cx": 16.0, "cy": 12.0, "w": 32, "h": 24,
            "frames": [{"file_path": f"{i}.png", "transform_matrix": eye} for i in range(3)]}
    nan, inf = float("nan"), float("inf")
    edits = [("fl_x", 0), ("fl_x", nan), ("fl_x", inf), ("fl_x", -5), ("fl_x", "30"), ("fl_x", None), ("cx", 1e309),
             ("w", -1), ("h", 1e12), ("k1", nan), ("k1", 1e30), ("camera_model", "OPENCV_FISHEYE"), ("frames", []),
             ("frames", None), ("frames", "x"), ("frames", [1, 2]), ("frames", [{"file_path": "../../etc/passwd"}] * 2),
             ("frames", [{"file_path": "0.png", "transform_matrix": [[nan] * 4] * 4}] * 3),
             ("frames", [{"file_path": "0.png", "transform_matrix": [[1, 0, 0]] * 3}] * 3),
             ("frames", [{"file_path": "0.png", "transform_matrix": "eye"}] * 3),
             ("frames", [{"file_path": "0.png", "transform_matrix": [[0] * 4] * 4}] * 3),
             ("frames", [{"file_path": 5, "transform_matrix": eye}] * 3), ("frames", [{}] * 3)]
    out = []
    for key, value in edits:
        doc = dict(base, **{key: value})
        files = {f"{i}.png": img for i in range(3)}
        files["transforms.json"] = json.dumps(doc).encode()
        out.append(Input("transforms_json", f"{key}={json.dumps(value)[:30]}", files, reader="transforms",
                         arg="transforms.json"))
    for raw in (b"", b"{", b"[]", b"null", b'"x"', b"\xff\xfe", b'{"frames": 1e999}', b"[" * 100000):
        out.append(Input("transforms_json", f"raw {raw[:8]!r}", {"transforms.json": raw}, reader="transforms",
                         arg="transforms.json"))
    text = json.dumps(base).encode()
    for _ in range(n):
        files = {f"{i}.png": img for i in range(3)}
        files["transforms.json"] = mutate(text, rng, int(rng.integers(1, 6)))
        out.append(Input("transforms_json", "mutated", files, reader="transforms", arg="transforms.json"))
    return out


def at_limits(rng) -> list:
    """The largest photo within the documented limits (49 MP, under serve's 50 MP), a decode's peak memory."""
    img = rng.integers(0, 256, (7000, 7000, 3), np.uint8)
    data = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, 30])[1].tobytes()
    return [Input("at_limits", "49 MP noise photo", {"x.jpg": data}, reader="image", arg="x.jpg"),
            Input("at_limits", "decode 49 MP noise photo", {"x.jpg": data},
                  argv=["decode", "{d}/x.jpg", "-o", "{d}/out", "--views", "1", "--size", "16"], outputs=("out",))]


def misc(seeds, rng, scale) -> list:
    return (wrong_extensions(seeds, rng) + odd_paths(seeds) + option_values(seeds) + at_limits(rng)
            + transforms(seeds, rng, max(1, int(1200 * scale))))
