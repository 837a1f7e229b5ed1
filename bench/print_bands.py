"""`snapshot3d bench print-bands`: which bands a print and a phone keep per unit of host fidelity, and the
print codec's candidate band sets through the real channel (sheet -> `simulate` -> `scan`).

- `response` rows: carriers over all 27 detail bands (luma, red-green, yellow-blue x Haar levels 1-3 x
  LH, HL, HH; equal energy per coefficient) hold a scene's planes in each host at the print codec's host
  fidelity; per capture and band, the gain of the carriers' partial readings against the digital
  snapshot's and the noise left, relative to the print noise model (`print_read.band_response`);
  `eta` = gain^2 / noise, what a unit of payload energy in that band is worth to the combining receiver.
- `pool` rows: each candidate band set (`CANDIDATES`: the codec's own and others) embedded, captured with
  the same seeds and read by the combining receiver: `restore_psnr` (orbit views against the scene's own),
  `host_psnr`, `host_ssim`.

Writes print_bands.{csv,json,png} under --out."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from snapshot3d import formats
from snapshot3d.codecs import bands, print_carriers, print_embed, print_read
from snapshot3d.errors import UserError
from snapshot3d.metrics import ssim
from snapshot3d.scanner.backgrounds import load_host
from snapshot3d.scanner.qr import scene_meta
from snapshot3d.scene import load_scene_file

from .codec_print import capture, heldout_hosts
from .common import SEVERITIES, ViewJudge, bench_progress, capture_seeds, psnr, pyplot, write_report

__all__ = ["bench_print_bands_command", "CANDIDATES"]

CANDIDATES = {
    "print-1": print_carriers.PRINT_BANDS,
    "chroma-4px": {"RG2LH": 1.0, "RG2HL": 1.0, "YB2LH": 1.0, "YB2HL": 1.0, "Y2HH": 1.0, "RG2HH": 0.5},
    "chroma-8px": {"RG2LH": 1.0, "RG2HL": 1.0, "RG3LH": 4.0, "RG3HL": 4.0, "RG3HH": 4.0, "YB2LH": 1.0,
                   "YB2HL": 1.0, "Y2HH": 1.0},
    "luma-chroma": {"Y2LH": 0.5, "Y2HL": 0.5, "Y2HH": 1.0, "RG2LH": 1.0, "RG2HL": 1.0, "YB2LH": 1.0, "YB2HL": 1.0},
}
"""band sets measured by the `pool` rows: name -> bands and relative energy per coefficient"""


def _hosts(names: str, heldout: int) -> dict[str, np.ndarray]:
    hosts = {h: load_host("builtin:" + h) for h in names.split(",") if h}
    hosts.update({Path(p).stem: load_host(p) for p in heldout_hosts(heldout)})
    return hosts


def bench_print_bands_command(args) -> int:
    out = Path(args.out)
    sevs = [s for s in args.severities.split(",") if s]
    names = [n for n in args.pools.split(",") if n] or list(CANDIDATES)
    for what, given, known in (("--severities", sevs, SEVERITIES), ("--pools", names, list(CANDIDATES))):
        unknown = [x for x in given if x not in known]
        if unknown or not given:
            raise UserError(f"{what}: unknown {', '.join(unknown) or '(none given)'}; choose from {', '.join(known)}")
    pools = {n: CANDIDATES[n] for n in names}
    hosts = _hosts(args.hosts, args.heldout)
    scenes = {Path(s).stem: load_scene_file(s) for s in args.scenes.split(",")}
    first = next(iter(scenes.values()))
    every = print_carriers.make_layout(first.resolution, first.channels, {b: 1.0 for b in bands.DETAIL_BANDS})
    per_host = sum(len(capture_seeds(s, args.seeds)) for s in sevs)
    judges = {name: ViewJudge(scene, args.size) for name, scene in scenes.items()}   # reference views, once
    rows = []
    with bench_progress(len(hosts) * per_host * (1 + len(pools) * len(scenes)), "captures") as bar:
        for hname, host in hosts.items():
            host8 = np.round(host * 255) / 255
            meta = scene_meta(first, formats.PRINT_CODEC)
            snap, _ = print_embed.embed_values(host, every, print_embed.carrier_values(every, first.planes()))
            for sev in sevs:
                for seed in capture_seeds(sev, args.seeds):
                    rect = capture(snap, meta, sev, seed)
                    bar.update(1)
                    if rect is None:
                        continue
                    gain, noise = print_read.band_response(rect, snap, every)
                    rows += [{"kind": "response", "host": hname, "severity": sev, "seed": seed, "band": b,
                              "gain": float(g), "noise": float(n), "eta": float(g * g / max(n, 1e-30))}
                             for b, g, n in zip(every.bands, gain, noise)]
            for sname, scene in scenes.items():
                judge, meta = judges[sname], scene_meta(scene, formats.PRINT_CODEC)
                for name, pool in pools.items():
                    lay = print_carriers.make_layout(scene.resolution, scene.channels, pool)
                    snap, _ = print_embed.embed_values(host, lay, print_embed.carrier_values(lay, scene.planes()))
                    base = {"kind": "pool", "pool": name, "scene": sname, "host": hname,
                            "host_psnr": psnr(snap / 255, host8), "host_ssim": ssim(snap / 255, host8)}
                    for sev in sevs:
                        for seed in capture_seeds(sev, args.seeds):
                            rect = capture(snap, meta, sev, seed)
                            bar.update(1)
                            row = dict(base, severity=sev, seed=seed, detected=int(rect is not None))
                            if rect is not None:
                                planes = print_read.restore_layout(lay, *print_read.read_carriers(rect, lay))[0]
                                row["restore_psnr"] = judge.planes_psnr(planes)
                            rows.append(row)
    summary = summarise(rows, sevs)
    doc = write_report(out, "print_bands", rows, {"severities": sevs, "hosts": list(hosts), "seeds": args.seeds,
                                                  "scenes": list(scenes),
                                                  "pools": pools, **summary})
    chart(out / "print_bands.png", doc)
    for name, per in summary["pools_median"].items():
        print(name, " ".join(f"{s} {v:.2f}" for s, v in per.items() if v is not None))
    return 0


def summarise(rows: list[dict], sevs: list[str]) -> dict:
    """Medians: eta per band and severity; restore_psnr per pool and severity, host_psnr/ssim per pool."""
    def med(xs):
        xs = [x for x in xs if x is not None]
        return float(np.median(xs)) if xs else None

    resp = [r for r in rows if r["kind"] == "response"]
    pool = [r for r in rows if r["kind"] == "pool"]
    band_names = list(dict.fromkeys(r["band"] for r in resp))
    eta = {s: {b: med([r["eta"] for r in resp if r["severity"] == s and r["band"] == b]) for b in band_names}
           for s in sevs}
    names = list(dict.fromkeys(r["pool"] for r in pool))
    per = {n: {s: med([r.get("restore_psnr") for r in pool if r["pool"] == n and r["severity"] == s]) for s in sevs}
           for n in names}
    host = {n: {k: med([r[k] for r in pool if r["pool"] == n]) for k in ("host_psnr", "host_ssim")} for n in names}
    return {"eta_median": eta, "pools_median": per, "pools_host": host}


def chart(path: Path, doc: dict) -> None:
    plt = pyplot()
    fig, (a, b) = plt.subplots(1, 2, figsize=(14, 5), gridspec_kw={"width_ratios": [2, 1]})
    sevs = [s for s in doc["severities"] if doc["eta_median"].get(s)]
    names = list(next(iter(doc["eta_median"].values())))
    x = np.arange(len(names))
    for i, s in enumerate(sevs):
        vals = np.array([doc["eta_median"][s][n] or 0.0 for n in names])
        a.bar(x + i / (len(sevs) + 1), vals / max(vals.max(), 1e-30), 1 / (len(sevs) + 1), label=s)
    a.set_xticks(x + 0.4, names, rotation=90, fontsize=7)
    a.set(ylabel="gain^2 / noise per unit energy (of the best band)", title="what each band keeps")
    a.legend(fontsize=8)
    for n, per in doc["pools_median"].items():
        ss = [s for s in doc["severities"] if per.get(s) is not None]
        b.plot(ss, [per[s] for s in ss], "o-", label=f"{n} (host SSIM {doc['pools_host'][n]['host_ssim']:.3f})")
    b.set(ylabel="restore_psnr (dB), median", title=f"band sets, combining receiver; {doc['cores']} cores")
    b.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
