"""`snapshot3d bench print-predict`: the print channel's model (`snapshot3d.codecs.print_channel`) fitted on real
simulated captures, and its predictions of each scene's restore checked against measured restores.

For each bench scene (spot at 16x4, 24x4, 32x4, 48x4 and lego at 48x4, `bench/models/`) and host, the
print snapshot is captured `--seeds` times at `moderate` (simulate + scan): measured `restore_psnr` (views
at 128x128 against the scene's own), and the channel its pilots measure (gain, unit noise). The model's
constants are the medians over all captures; they are written to the print entry of
`snapshot3d/assets/budget-curves.json` ("channel"), which `fit --budget auto --medium print` uses to
predict each rung's restore from its own planes. Then each scene is predicted with those constants
(`--draws` noise draws per host) and compared with what was measured: per scene, the medians over hosts
and seeds; the curve of payload against restore_psnr that the ladder used before is shown beside them.

Writes print_predict.{csv,json,png} under --out."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from snapshot3d import formats
from snapshot3d.codecs.print_channel import ChannelModel, measure, predicted_planes
from snapshot3d.codecs.print_embed import embed
from snapshot3d.scanner.backgrounds import load_host
from snapshot3d.scanner.qr import scene_meta
from snapshot3d.scene import load_scene_file
from snapshot3d.viewer.media import restore_print

from .codec_print import heldout_hosts
from .common import ViewJudge, bench_progress, pyplot, through_channel, write_report

__all__ = ["bench_print_predict_command", "SCENES", "write_channel"]

SCENES = ("spot-r16c4", "spot-r24c4", "spot-r32c4", "spot-r48c4", "lego-print")
MODELS = Path(__file__).resolve().parent / "models"


def write_channel(channel: ChannelModel, severity: str, source: str) -> Path:
    """The print channel's constants into the print entry of the package's budget-curves.json."""
    from snapshot3d.paths import asset
    from snapshot3d.train.field.budget import CURVES_FILE

    path = asset(CURVES_FILE)
    curves = json.loads(path.read_text())
    curves.setdefault("print", {})["channel"] = {"severity": severity, "gain": round(channel.gain, 4),
                                                 "unit": round(channel.unit, 4), "source": source}
    path.write_text(json.dumps(curves, indent=2) + "\n")
    return path


def bench_print_predict_command(args) -> int:
    from snapshot3d.train.field.budget import codec_psnr

    out = Path(args.out)
    hosts = {h: load_host("builtin:" + h) for h in args.hosts.split(",") if h}
    hosts.update({Path(p).stem: load_host(p) for p in heldout_hosts(args.heldout)})
    scenes = {s: load_scene_file(MODELS / f"{s}.s3d") for s in args.scenes.split(",")}
    rows, judges = [], {}
    with bench_progress(len(scenes) * len(hosts) * args.seeds, "captures") as bar:
        for sname, scene in scenes.items():
            judge = judges[sname] = ViewJudge(scene, args.size)  # renders the reference views once per scene
            r, c = scene.resolution, scene.channels
            for hname, host in hosts.items():
                snap = embed(host, scene.planes())
                for seed in range(args.seeds):
                    cap = through_channel(snap, scene_meta(scene, formats.PRINT_CODEC), args.severity, seed)
                    bar.update(1)
                    if cap is None:
                        continue
                    ch = measure(snap, cap, r, c)
                    rows.append({"kind": "capture", "scene": sname, "host": hname, "seed": seed, "values": scene.codes.size,
                                 "gain": ch.gain, "unit": ch.unit,
                                 "restore_psnr": judge.planes_psnr(restore_print(cap, r, c)[0])})
    caps = [x for x in rows if x["kind"] == "capture"]
    channel = ChannelModel(float(np.median([x["gain"] for x in caps])), float(np.median([x["unit"] for x in caps])))
    rng = np.random.default_rng(0)
    summary = {}
    for sname, scene in scenes.items():
        judge = judges[sname]
        pred = [judge.planes_psnr(predicted_planes(host, scene.planes(), channel, rng))
                for host in hosts.values() for _ in range(args.draws)]
        rows += [{"kind": "predicted", "scene": sname, "values": scene.codes.size, "restore_psnr": p} for p in pred]
        measured = [x["restore_psnr"] for x in caps if x["scene"] == sname]
        summary[sname] = {"values": int(scene.codes.size), "measured": float(np.median(measured)),
                          "predicted": float(np.median(pred)), "curve": codec_psnr("print", int(scene.codes.size))}
        s = summary[sname]
        s["error_db"], s["curve_error_db"] = s["predicted"] - s["measured"], s["curve"] - s["measured"]
        print(f"{sname}: measured {s['measured']:.2f} dB, predicted {s['predicted']:.2f} (curve {s['curve']:.2f})")
    errors = [abs(s["error_db"]) for s in summary.values()]
    doc = write_report(out, "print_predict", rows, {
        "severity": args.severity, "hosts": list(hosts), "seeds": args.seeds, "draws": args.draws,
        "channel": {"gain": channel.gain, "unit": channel.unit}, "scenes": summary,
        "max_abs_error_db": max(errors), "curve_max_abs_error_db": max(abs(s["curve_error_db"]) for s in summary.values())})
    if not args.quick:
        from snapshot3d.train.field.channel_fit import write_stored_responses
        from snapshot3d.train.field.curves import print_channel
        write_channel(channel, args.severity, "snapshot3d bench print-predict (medians over "
                      f"{len(caps)} {args.severity} captures of {len(scenes)} scenes in {len(hosts)} hosts)")
        print(f"wrote {write_stored_responses(print_channel())}")   # as fitting reads it back (rounded)
    _chart(out / "print_predict.png", summary, doc)
    return 0


def _chart(path: Path, summary: dict, doc: dict) -> None:
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7, 5))
    lo = min(min(s["measured"], s["predicted"], s["curve"]) for s in summary.values()) - 1
    hi = max(max(s["measured"], s["predicted"], s["curve"]) for s in summary.values()) + 1
    ax.plot([lo, hi], [lo, hi], color="grey", lw=1)
    for name, s in summary.items():
        ax.plot(s["measured"], s["predicted"], "o", color="C0")
        ax.plot(s["measured"], s["curve"], "x", color="C3")
        ax.annotate(name, (s["measured"], s["predicted"]), fontsize=8)
    ax.plot([], [], "o", color="C0", label=f"per-scene prediction (max error {doc['max_abs_error_db']:.1f} dB)")
    ax.plot([], [], "x", color="C3", label=f"payload curve (max error {doc['curve_max_abs_error_db']:.1f} dB)")
    ax.set(xlabel=f"measured restore_psnr at {doc['severity']} (dB)", ylabel="expected restore_psnr (dB)",
           title=f"print channel model: gain {doc['channel']['gain']:.2f}, unit noise {doc['channel']['unit']:.1f}; "
                 f"{doc['cores']} cores")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
