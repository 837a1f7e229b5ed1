"""`snapshot3d bench print-digital`: the digital payload (`bench.digital_payload`: quantised planes, CRC,
convolutional code, nested layers) against the shipped analog carriers (`codecs.print_carriers`' codec; `print-1`
when its results were written) on the same scenes, hosts, severities and seeds, each through the real channel (sheet -> `simulate` -> `scan`).

Rows (print_digital.csv), per scene, host, severity and seed:
- `print`: the shipped codec: `restore_psnr` (views at --size against the scene's own) and plane RMSE;
- `digital`: the candidate: layers whose CRC held, stream bits restored, the data carriers' SNR by the
  pilots, `restore_psnr` and plane RMSE;
- `digital-ideal`: what any code on the same carriers could do in that capture: the BPSK mutual information
  of its soft values (bits) and the best `restore_psnr` that many bits allow for the scene's planes (the
  Gaussian separation bound of `bench capacity`, rendered through the scene's noise curve);
- `ldpc` (with `--codes` naming it): the near-capacity candidate (`bench.digital_ldpc`: an entropy-coded embedded
  transform coder, nested IRA-LDPC layers of rates 1/5 to 2/3 with a CRC each, soft BP decoding), with the same
  columns as `digital`;
- `source-at-mi` (with `ldpc`): that transform coder given exactly the mutual information's bits of the `ldpc`
  capture, losslessly (a capacity-achieving channel code under the real source coder).
Writes print_digital.{csv,json,png} under --out."""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from snapshot3d import formats
from snapshot3d.codecs.print_embed import embed
from snapshot3d.errors import UserError
from snapshot3d.scanner.backgrounds import load_host
from snapshot3d.scanner.qr import scene_meta
from snapshot3d.scene import load_scene_file
from snapshot3d.viewer.media import restore_print

from .codec_print import heldout_hosts
from .common import SEVERITIES, ViewJudge, bench_progress, capture_seeds, median, pyplot, through_channel, write_report
from .digital_payload import DESIGN, embed_digital, layer_sizes, read_digital, sent_bits

__all__ = ["bench_print_digital_command"]

METHODS = ("print", "digital", "digital-ideal", "ldpc", "source-at-mi")
CODES = ("conv", "ldpc")


def _ideal_psnr(judge: ViewJudge, curve, bits: float, planes: np.ndarray) -> float:
    from .capacity_model import best_plane_rmse, psnr_at
    return psnr_at(curve, best_plane_rmse(bits, planes.size, float(np.var(planes))))


def _ldpc_rows(base: dict, cap: np.ndarray, judge: ViewJudge, planes: np.ndarray, sent: np.ndarray) -> list[dict]:
    from .digital_ldpc import read_ldpc
    from .digital_source import decode_segments, encode_segments

    r, c = planes.shape[-1], planes.shape[1]
    got, rd = read_ldpc(cap, r, c, sent=sent)
    info = {"layers": rd.layers, "bits": rd.bits, "snr_db": rd.snr_db, "mutual_info_bits": rd.mutual_info_bits}
    rmse = float(np.sqrt(np.mean((got - planes) ** 2)))
    rows = [dict(base, method="ldpc", restore_psnr=judge.planes_psnr(got), plane_rmse=rmse, **info)]
    mi = int(max(rd.mutual_info_bits, 0.0))
    ideal = decode_segments(encode_segments(planes, [mi]), r, c) if mi > 18 else np.zeros_like(planes)
    rows.append(dict(base, method="source-at-mi", **info, restore_psnr=judge.planes_psnr(ideal),
                     plane_rmse=float(np.sqrt(np.mean((ideal - planes) ** 2)))))
    return rows


def _scene_rows(sname, scene, hosts, severities, seeds, size, bar, codes=("conv",)) -> list[dict]:
    from .capacity_model import noise_curve

    judge = ViewJudge(scene, size)
    curve = noise_curve(judge)
    planes, r, c = scene.planes(), scene.resolution, scene.channels
    meta = scene_meta(scene, formats.PRINT_CODEC)
    sent = {"digital": sent_bits(planes)}
    rows = []
    for hname, host in hosts.items():
        snaps = {"print": embed(host, planes)}
        if "conv" in codes:
            snaps["digital"] = embed_digital(host, planes)
        if "ldpc" in codes:
            from .digital_ldpc import coded_bits, embed_ldpc
            snaps["ldpc"], sent["ldpc"] = embed_ldpc(host, planes), coded_bits(planes)
        for sev in severities:
            for seed in capture_seeds(sev, seeds):
                for method, snap in snaps.items():
                    cap = through_channel(snap, meta, sev, seed)
                    base = {"scene": sname, "host": hname, "severity": sev, "seed": seed, "detected": int(cap is not None)}
                    if cap is None:
                        rows.append(dict(base, method=method))
                        continue
                    if method == "print":
                        got = restore_print(cap, r, c)[0]
                        rows.append(dict(base, method=method, restore_psnr=judge.planes_psnr(got),
                                         plane_rmse=float(np.sqrt(np.mean((got - planes) ** 2)))))
                        continue
                    if method == "ldpc":
                        rows += _ldpc_rows(base, cap, judge, planes, sent["ldpc"])
                        continue
                    got, rd = read_digital(cap, r, c, sent=sent["digital"])
                    info = {"layers": rd.layers, "bits": rd.bits, "snr_db": rd.snr_db, "mutual_info_bits": rd.mutual_info_bits}
                    rows.append(dict(base, method="digital", restore_psnr=judge.planes_psnr(got),
                                     plane_rmse=float(np.sqrt(np.mean((got - planes) ** 2))), **info))
                    rows.append(dict(base, method="digital-ideal", **info,
                                     restore_psnr=_ideal_psnr(judge, curve, rd.mutual_info_bits, planes)))
                bar.update(1)
    return rows


def bench_print_digital_command(args) -> int:
    out = Path(args.out)
    t0 = time.time()
    severities = [s for s in args.severities.split(",") if s]
    unknown = [s for s in severities if s not in SEVERITIES]
    if unknown or not severities:
        raise UserError(f"--severities: unknown {', '.join(unknown) or '(none given)'}; choose from {', '.join(SEVERITIES)}")
    hosts = {h: load_host("builtin:" + h) for h in args.hosts.split(",") if h}
    hosts.update({Path(p).stem: load_host(p) for p in heldout_hosts(args.heldout)})
    codes = [c for c in getattr(args, "codes", "conv").split(",") if c]
    if not codes or set(codes) - set(CODES):
        raise UserError(f"--codes: unknown {', '.join(sorted(set(codes) - set(CODES))) or '(none given)'}; "
                        f"choose from {', '.join(CODES)}")
    if "ldpc" in codes:
        try:
            import ldpc  # noqa: F401
        except ImportError:
            raise UserError("--codes ldpc needs the ldpc package: pip install 'snapshot3d[test]' (or pip install ldpc)") from None
    scenes = {Path(p).stem: load_scene_file(p) for p in args.scenes.split(",")}
    per = sum(len(capture_seeds(s, args.seeds)) for s in severities)
    rows = []
    with bench_progress(len(scenes) * len(hosts) * per, "captures") as bar:
        for sname, scene in scenes.items():
            rows += _scene_rows(sname, scene, hosts, severities, args.seeds, args.size, bar, codes)
    summary = {m: {s: {k: median([r for r in rows if r["method"] == m and r["severity"] == s], k)
                       for k in ("restore_psnr", "plane_rmse", "bits", "mutual_info_bits", "snr_db", "layers")}
                   for s in severities} for m in METHODS}
    by_scene = {n: {m: {s: median([r for r in rows if r["scene"] == n and r["method"] == m and r["severity"] == s],
                                  "restore_psnr") for s in severities} for m in METHODS} for n in scenes}
    doc = write_report(out, "print_digital", rows, {
        "scenes": list(scenes), "hosts": list(hosts), "seeds": args.seeds, "view_size": args.size, "codes": codes,
        "design": {"data_carriers": DESIGN.carriers, "layers": [
            {"carriers": n, "repetitions": rep, "info_bits": info} for n, rep, info in layer_sizes(DESIGN)]},
        "ldpc_design": _ldpc_design() if "ldpc" in codes else None,
        "summary": summary, "by_scene": by_scene, "seconds": round(time.time() - t0, 1)})
    _chart(out / "print_digital.png", doc, severities)
    for m in METHODS:
        if all(summary[m][s]["restore_psnr"] is None for s in severities):
            continue
        print(m, {s: round(v["restore_psnr"], 2) for s, v in summary[m].items() if v["restore_psnr"] is not None})
    return 0


def _ldpc_design() -> dict:
    from .digital_ldpc import LDPC_DESIGN, layer_plan
    return {"data_carriers": LDPC_DESIGN.carriers, "heavy_degree": LDPC_DESIGN.heavy_degree,
            "heavy_share": LDPC_DESIGN.heavy_share,
            "layers": [{"carriers": n, "code_bits": k, "rate": round(k / n, 3)} for n, k in layer_plan(LDPC_DESIGN)]}


def _chart(path: Path, doc: dict, severities: list[str]) -> None:
    plt = pyplot()
    fig, ax = plt.subplots(1, 2, figsize=(12, 4.5))
    x = np.arange(len(severities))
    for m in METHODS:
        ax[0].plot(x, [doc["summary"][m][s]["restore_psnr"] or np.nan for s in severities], "o-", label=m)
    ax[0].set_xticks(x, severities)
    ax[0].set(ylabel="restore_psnr (dB), median", title="analog carriers (print) against a digital payload")
    ax[0].legend(fontsize=8)
    for m, key, label in (("digital", "mutual_info_bits", "ideal code on these carriers (mutual information)"),
                          ("digital", "bits", "delivered by CRC + conv. code + layers"),
                          ("ldpc", "bits", "delivered by CRC + LDPC layers")):
        ax[1].plot(x, [doc["summary"][m][s][key] or np.nan for s in severities], "o-", label=label)
    ax[1].set_xticks(x, severities)
    ax[1].set_yscale("log")
    ax[1].set(ylabel="payload bits per capture, median", title="what the carriers could carry and what was carried")
    ax[1].legend(fontsize=8)
    fig.suptitle(f"snapshot3d bench print-digital ({', '.join(doc['scenes'])}; {doc['cores']} cores)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
