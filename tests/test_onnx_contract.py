"""The ONNX contract for third-party clients (docs/onnx-contract.md): the shipped graphs have the documented
names, shapes, dtypes and doc strings; they reproduce the committed conformance vectors in onnxruntime; and
the page's constructions (spread matrix, interpolation weights, table rows, 8-bit rounding), written here
from the page's text alone, give what the product computes."""
from pathlib import Path

import cv2
import numpy as np
import onnxruntime as ort
import pytest

from snapshot3d import formats
from snapshot3d.paths import asset
from snapshot3d.viewer.runtime import model_path

ROOT = Path(__file__).resolve().parents[1]
VECTORS = ROOT / "tests" / "data" / "onnx-conformance.npz"
SNAPSHOT = ROOT / "tests" / "data" / "spot-snapshot.png"
CONTRACT = {  # kind: (inputs, outputs) as (name, shape, dtype); str dims are symbolic
    "restore": ([("snapshot", [1, 3, 380, 380], "tensor(float)")], [("secret", [1, 24, 95, 95], "tensor(float)")]),
    **{f"project{v}": ([("planes", [3, 12, "R", "R"], "tensor(float)"), ("interp", ["B", "R"], "tensor(float)")],
                       [("tables", [3, None, h], "tensor(float)")]) for v, h in (("", 32), ("-tri-dec-2", 64))},
    **{f"field{v}": ([("tables", [3, None, h], "tensor(float)"), ("rows", [None, 3], "tensor(int64)")],
                     [("density_logit", [None], "tensor(float)"), ("rgb", [None, 3], "tensor(float)")])
       for v, h in (("", 32), ("-tri-dec-2", 64))},
    "restore-print": ([("snapshot", [1, 3, 380, 380], "tensor(float)"), ("chips", ["N", "K"], "tensor(int64)"),
                       ("base", ["N", "K"], "tensor(float)"), ("place", ["S"], "tensor(int64)"),
                       ("scale", ["M"], "tensor(float)"), ("prior", ["M"], "tensor(float)"),
                       ("pilots", [256], "tensor(float)"), ("folded", ["F"], "tensor(int64)"),
                       ("fold_amp", ["F"], "tensor(float)"), ("dct", ["R", "R"], "tensor(float)"),
                       ("prior_rest", [], "tensor(float)")],
                      [("planes", [3, "C", "R", "R"], "tensor(float)"), ("reading", [3], "tensor(float)")]),
}

# Tolerances (docs/onnx-contract.md, "Conformance vectors", states the same). Another CPU's onnxruntime kernels
# (AVX2 or AVX-512 blocking, FMA or not) sum in another order: a float32 sum of n terms then moves by at most
# about n u sum|terms|, u = 2^-24 = 6e-8. The deepest sums are project's 2 x 64 + 36 = 164 terms (1e-5 of the
# terms' size), field's 3 + 32 + 32 per point and the print receiver's 256 pilots, so a float32 graph output
# compared on the same inputs must satisfy |got - want| <= ATOL + RTOL |want|, 10x that bound, scaled with the
# value (field logits reach 48). A 1% drift of any value above 0.01 in size still fails it.
RTOL, ATOL = 1e-4, 1e-4
# restore_secret is stored as float16 (a relative step of 2^-10: 4.9e-4 rounding) after 33 convolutions.
SECRET_RTOL, SECRET_ATOL = 2e-3, 2e-3
# 8-bit codes: a value within a kernel difference of a half-code tie may round the other way; at most 0.1% of
# the codes (98 of 98,304 for the vectors' planes) may differ, each by one code. Measured: 2 of 98,304.
CODE_FLIP_SHARE = 1e-3
# Float inputs that numpy makes (the layout's carriers and DCT, the interpolation weights): numpy's float64 sin, cos
# and exp take other SIMD paths on other CPUs (AVX-512) and may differ in the last bit, which cast to float32 moves
# a value by at most one float32 step (1.2e-7 of it): compare with 1e-6 of the value.
INPUT_RTOL, INPUT_ATOL = 1e-6, 1e-9
# The scan of the example photo (print_capture) goes through OpenCV's homography fit and warps. OpenCV 5.1.0's
# least-squares cv2.findHomography differs from 5.0.0's by 3e-5 px on the sheet, which flips 0.12% of the
# capture's codes by one and 9 of them by 2-18 (dark pixels where the scan's tone curve is steep). At most 0.5% of
# the codes may differ, at most 0.01% (43 of 433,200) by more than one; the planes read from it are held to 0.01,
# the reading's noise powers to 1e-3 of themselves.
CAPTURE_FLIP_SHARE, CAPTURE_JUMP_SHARE = 5e-3, 1e-4


def _close(got, want, rtol=RTOL, atol=ATOL) -> bool:
    """|got - want| <= atol + rtol |want| everywhere, and the same test refuses want drifted by 1% (the tolerance
    still catches a real change on these values)."""
    got, want = np.asarray(got, np.float64), np.asarray(want, np.float64)
    if np.any(want != 0):
        assert not np.all(np.abs(want * 1.01 - want) <= atol + rtol * np.abs(want)), "tolerance too loose for them"
    return bool(np.all(np.abs(got - want) <= atol + rtol * np.abs(want)))


def _capture_flips_ok(codes, want_codes) -> bool:
    """The scan's codes: at most CAPTURE_FLIP_SHARE differ, at most CAPTURE_JUMP_SHARE by more than one."""
    d = np.abs(np.asarray(codes, int) - np.asarray(want_codes, int))
    return np.mean(d > 0) <= CAPTURE_FLIP_SHARE and np.mean(d > 1) <= CAPTURE_JUMP_SHARE


def _code_flips_ok(codes, want_codes) -> bool:
    """At most CODE_FLIP_SHARE of the 8-bit codes differ, each by one."""
    d = np.abs(np.asarray(codes, int) - np.asarray(want_codes, int))
    return d.max() <= 1 and np.mean(d > 0) <= CODE_FLIP_SHARE


@pytest.fixture(scope="module")
def vectors():
    with np.load(VECTORS) as z:
        return {k: z[k] for k in z.files}


def _session(kind):
    """kind as in CONTRACT: 'project-tri-dec-2' is that decoder's project graph, 'project' the default one's."""
    graph, _, decoder = kind.partition("-") if kind.startswith(("project-", "field-")) else (kind, "", None)
    return ort.InferenceSession(str(model_path(graph, decoder=decoder)), providers=["CPUExecutionProvider"])


def _same(spec, got):
    name, shape, dtype = spec
    dims = [d if isinstance(d, int) else None for d in got.shape]
    want = [d if isinstance(d, int) else None for d in shape]
    return got.name == name and got.type == dtype and dims == want


@pytest.mark.parametrize("kind", sorted(CONTRACT))
def test_graph_signature_and_doc_string(kind):
    s = _session(kind)
    ins, outs = CONTRACT[kind]
    assert [i.name for i in s.get_inputs()] == [n for n, _, _ in ins]
    assert all(_same(spec, got) for spec, got in zip(ins, s.get_inputs())), s.get_inputs()
    assert all(_same(spec, got) for spec, got in zip(outs, s.get_outputs())), s.get_outputs()
    meta = s.get_modelmeta()
    assert len(meta.description) > 150, f"{kind}: the model carries no contract in its doc string"
    for name, _, _ in ins + outs:
        assert name in meta.description
    props = meta.custom_metadata_map
    assert {"decoder_version", "snapshot_size", "c_max"} <= set(props)
    if kind.startswith(("project", "field")):
        assert props["decoder_version"] == (kind.partition("-")[2] or formats.DECODER_VERSION)
    if kind.startswith("restore"):   # the codec ids the graph reads, comma-separated, newest first
        assert props["codec_id"] == {"restore": "hinet-3", "restore-print": "print-2,print-1"}[kind]
    else:                            # the renderer's graphs serve every codec: they name none
        assert "codec_id" not in props
    if kind == "restore":
        assert "(1, 24, 95, 95)" in meta.description and "RGB" in meta.description


def test_contract_page_matches_the_shapes():
    text = (ROOT / "docs" / "onnx-contract.md").read_text()
    assert "`secret` float32 (1, 24, 95, 95)" in text and "190" not in text


def _spread(r, g=95):
    """U from the page: pos_i = i (R - 1) / 94, linear weights onto texels j, j + 1."""
    u = np.zeros((g, r))
    for i in range(g):
        pos = i * (r - 1) / (g - 1)
        j = min(int(np.floor(pos)), r - 2)
        u[i, j], u[i, j + 1] = 1 - (pos - j), pos - j
    return u


def _codes(x):
    """the page's 8-bit rounding: code = round((clip(x, -1, 1) + 1) / 2 * 255)"""
    return np.round((np.clip(x, -1, 1) + 1) / 2 * 255).astype(int)


def test_restore_graph_reproduces_the_vectors(vectors):
    rgb = vectors["restore_snapshot"]
    assert np.array_equal(rgb, cv2.cvtColor(cv2.imread(str(SNAPSHOT)), cv2.COLOR_BGR2RGB))  # the file's pixels
    x = (rgb.astype(np.float32) / 255).transpose(2, 0, 1)[None]
    secret = _session("restore").run(None, {"snapshot": x})[0][0]
    want = vectors["restore_secret"].astype(np.float32)
    assert _close(secret, want, SECRET_RTOL, SECRET_ATOL), np.abs(secret - want).max()
    # the page's unspread, from its text: X = P S P^T, P = pinv(U), first C channels of each plane
    meta = str(vectors["meta"])
    r, c = (int(v) for v in meta.split("|p=")[1].split("|")[0].split(","))
    p = np.linalg.pinv(_spread(r))
    s = secret.reshape(3, 8, 95, 95)[:, :c].astype(np.float64)
    codes, want_codes = _codes(p @ s @ p.T), _codes(vectors["planes"].astype(np.float64))
    assert codes.shape == want_codes.shape == (3, c, r, r)
    assert _code_flips_ok(codes, want_codes)  # a value on a rounding edge may flip by one code
    assert np.allclose(want_codes / 255 * 2 - 1, vectors["planes"], atol=1e-6)  # X = code / 255 * 2 - 1


def test_renderer_graphs_reproduce_the_vectors(vectors):
    from snapshot3d.viewer.bake import cell_coords, interp_matrix
    planes, b = vectors["planes"], 16
    r = planes.shape[-1]
    # interp from the page: t = clip((u + 1) / 2 (R - 1), 0, R - 1), weights on floor(t) (at most R - 2) and +1
    u = (np.arange(b) + 0.5) / b * 2 - 1
    t = np.clip((u + 1) / 2 * (r - 1), 0, r - 1)
    j = np.minimum(np.floor(t), r - 2).astype(int)
    interp = np.zeros((b, r), np.float32)
    interp[np.arange(b), j], interp[np.arange(b), j + 1] = 1 - (t - j), t - j
    assert np.allclose(interp, vectors["project_interp"], atol=1e-6)
    assert np.allclose(interp, interp_matrix(cell_coords(b), r), atol=1e-6)
    padded = np.zeros((3, 12, r, r), np.float32)
    padded[:, :planes.shape[1]] = planes
    tables = _session("project").run(None, {"planes": padded, "interp": interp})[0]
    assert tables.shape == (3, b * b, 32) and _close(tables, vectors["project_tables"])
    cells = vectors["field_cells"]
    ix, iy, iz = cells.T
    rows = np.stack([iy * b + ix, iz * b + ix, iz * b + iy], 1).astype(np.int64)  # the page's rows
    assert np.array_equal(rows, vectors["field_rows"])
    logit, rgb, hidden = _session("field").run(["density_logit", "rgb", "hidden"], {"tables": tables, "rows": rows})
    assert _close(logit, vectors["field_density_logit"])
    assert _close(rgb, vectors["field_rgb"]) and rgb.min() >= 0 and rgb.max() <= 1
    assert logit.max() <= 15.0
    assert hidden.shape == (len(rows), 32) and _close(hidden, vectors["field_hidden"]) and hidden.min() >= 0
    # the page's head on `hidden`, with the shared decoder's last layer, gives the graph's own outputs
    with np.load(asset("decoder-tri-dec-1.npz")) as z:
        w, b = z["l2.weight"], z["l2.bias"]
    out = hidden @ w.T + b
    assert _close(np.minimum(out[:, 0], 15.0), logit) and _close(1 / (1 + np.exp(-out[:, 1:4])), rgb)


def _print_feeds(vectors):
    """The restore-print graph's inputs from the vectors, as the page says: the capture / 255 in NCHW, the
    index arrays as int64."""
    feeds = {k[len("print_"):]: v.astype(np.int64) if v.dtype == np.int32 else v for k, v in vectors.items()
             if k.startswith("print_") and k not in ("print_capture", "print_meta", "print_planes", "print_reading")}
    feeds["snapshot"] = (vectors["print_capture"].astype(np.float32) / 255).transpose(2, 0, 1)[None]
    return feeds


def test_print_graph_reproduces_the_vectors(vectors):
    """The print graph on the vectors' capture and layout gives their planes; the layout is still what the print
    codec writes (a sheet printed long ago must still read), and its DCT matrix is the page's formula."""
    from snapshot3d.codecs import print_carriers, print_feeds
    feeds = _print_feeds(vectors)
    assert sorted(feeds) == sorted(print_feeds.PRINT_GRAPH_INPUTS)
    planes, reading = _session("restore-print").run(None, feeds)
    assert _close(planes, vectors["print_planes"]), np.abs(planes - vectors["print_planes"]).max()
    assert _close(reading, vectors["print_reading"], atol=0)   # reading's noise power is 1.5e-3: relative only
    meta = str(vectors["print_meta"])
    codec = meta.split("|")[1]
    r, c = (int(v) for v in meta.split("|p=")[1].split("|")[0].split(","))
    assert codec == "print-2" and planes.shape == (3, c, r, r)
    for k, v in print_feeds.layout_feeds(print_carriers.print_layout(r, c, codec)).items():
        assert np.array_equal(v, feeds[k]) if v.dtype.kind == "i" else _close(v, feeds[k], INPUT_RTOL, INPUT_ATOL), k
    k, n = np.meshgrid(np.arange(r), np.arange(r), indexing="ij")   # D[k, n] from the page
    d = np.sqrt(np.where(k == 0, 1.0, 2.0) / r) * np.cos(np.pi * (2 * n + 1) * k / (2 * r))
    assert np.allclose(d, feeds["dct"], atol=1e-6)


def test_vectors_are_the_product_path(vectors):
    """The committed vectors equal what the product's own code makes from the shipped models now, stage by stage:
    each graph is compared on the committed inputs, so that a code rounded the other way upstream (one 8-bit step
    moves a logit by up to 3e-2) is judged as a code, not as a float drift downstream."""
    from snapshot3d.export.conformance import make_vectors, render_vectors
    models = {k: model_path(k) for k in ("restore", "restore-print", "project", "field")}
    fresh = make_vectors(models)
    assert sorted(fresh) == sorted(vectors)
    fresh.update(render_vectors(models, vectors["planes"]))
    code = lambda x: np.round((np.clip(x.astype(np.float32), -1, 1) + 1) / 2 * 255).astype(int)  # noqa: E731
    for k, v in vectors.items():
        if k == "print_capture":   # the scan of a photo: another OpenCV may fit and warp it a hair differently
            assert _capture_flips_ok(fresh[k], v), (k, int((fresh[k] != v).sum()))
        elif k == "print_planes":  # read from that capture: 0.1% of its values one code off moved them by 2.7e-3
            assert np.abs(fresh[k] - v).max() <= 0.01, (k, np.abs(fresh[k] - v).max())
        elif k == "planes":
            assert _code_flips_ok(code(fresh[k]), code(v)), (k, int((code(fresh[k]) != code(v)).sum()))
        elif k == "restore_secret":
            assert _close(fresh[k], v, SECRET_RTOL, SECRET_ATOL), k
        elif k == "print_reading":  # read from that capture too: OpenCV 5.1's moved it by 1.5e-4 of itself
            assert _close(fresh[k], v, rtol=1e-3, atol=0), (k, np.abs(fresh[k] / v - 1).max())
        elif k == "mark_dither":   # numpy's PCG64 draws: the same bits on every CPU
            assert np.array_equal(fresh[k], v), k
        elif v.dtype.kind == "f" and (k == "project_interp" or k.startswith("print_")):   # inputs numpy makes
            assert _close(fresh[k], v, INPUT_RTOL, INPUT_ATOL), k
        elif v.dtype.kind == "f":
            assert _close(fresh[k], v), (k, np.abs(fresh[k] - v).max())
        else:
            assert np.array_equal(fresh[k], v), k


def test_pixel_mark_reads_as_the_page_says(vectors):
    """The pixel metadata mark of the vectors' snapshot, read from the page's text alone (with the vectors' slots
    and dithers, and a Viterbi decoder of the 133/171 code), gives the snapshot's metadata line."""
    import struct
    import zlib

    from snapshot3d.scanner.pixelmeta import viterbi
    luma = vectors["restore_snapshot"].astype(np.float64) @ [0.299, 0.587, 0.114]
    k = np.arange(8)
    c = np.sqrt(np.where(k == 0, 1.0, 2.0) / 8)[:, None] * np.cos((2 * k[None] + 1) * k[:, None] * np.pi / 16)
    blocks = luma[:376, :376].reshape(47, 8, 47, 8)
    coef = np.stack([np.einsum("iyjx,y,x->ij", blocks, c[u], c[v]) for u, v in ((0, 1), (1, 0), (1, 1))], -1)
    coef = coef.reshape(-1)   # slot ((i * 47) + j) * 3 + f
    step, nbytes = 32.0, 38
    coded = 2 * (nbytes * 8 + 6)
    repeat = 6627 // coded
    slots = vectors["mark_slots"][:coded * repeat].reshape(coded, repeat)
    soft = np.cos(2 * np.pi * (coef - vectors["mark_dither"] * step) / step)[slots].sum(1)
    frame = np.packbits(viterbi(soft)).tobytes()
    assert len(frame) == nbytes and struct.unpack("<I", frame[-4:])[0] == zlib.crc32(frame[:-4])
    assert frame[0] == 2 and frame[1] == 1 and frame[2] == 3   # mark version, format version, codec 3: hinet-3
    flags, pos, fields = frame[3], 4, []
    for bit, fmt in enumerate(("<6e", "<3e", "<3e", "<2H", "<e")):
        if flags >> bit & 1:
            fields.append(struct.unpack_from(fmt, frame, pos))
            pos += struct.calcsize(fmt)
    meta = str(vectors["meta"])   # S3D1|hinet-3|b=...|o=...|t=...|p=R,C|s=...
    want = [tuple(float(x) for x in part[2:].split(",")) for part in meta.split("|")[2:]]
    assert len(fields) == len(want) == 5
    for got, w in zip(fields, want):
        assert np.allclose(got, w, rtol=1e-3, atol=1e-3), (got, w)   # float16 holds the text's 4 digits
