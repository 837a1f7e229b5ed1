"""Options of the `snapshot3d bench ...` commands. Option definitions only: the benchmarks themselves
live in `snapshot3d.bench` and are imported when a command runs (the product never imports them)."""
from __future__ import annotations

from snapshot3d.formats import FILE_REFINE_STEPS, MEDIA, SEVERITIES
from snapshot3d.lazy import lazy_command as _run

from .common import add_command as add

__all__ = ["add_commands"]


def _out(p) -> None:
    p.add_argument("--out", default=None, help="output folder (default: bench/results, or bench/results/quick "
                                               "with --quick, so that a smoke run never overwrites the results)")


def _through_print_options(p, seeds: int) -> None:
    """The photos of `bench decoders` and `bench e2e` (`decoders.e2e_rows`): hosts, severities, seeds, views."""
    p.add_argument("--hosts", default="coffee,chelsea", help="bundled host photos (held out from codec training)")
    p.add_argument("--heldout", type=int, default=2, help="also this many held-out host photos (../shared)")
    p.add_argument("--severities", default="mild,moderate,severe", help="comma-separated physical severities")
    p.add_argument("--seeds", type=int, default=seeds, help="simulated photos per severity and host")
    p.add_argument("--views", type=int, default=5, help="held-out ground-truth views per e2e_psnr")
    p.add_argument("--size", type=int, default=96, help="orbit view size for restore_psnr")


def _print_scene_options(p, heldout: int) -> None:
    """--out, and the photos of one print scene of `bench burst` and `bench print-ablation`: scene, hosts, views."""
    _out(p)
    p.add_argument("--scene", default="bench/models/spot-print-head-refit.s3d", help="scene file (fitted for print)")
    p.add_argument("--hosts", default="coffee,chelsea", help="bundled host photos")
    p.add_argument("--heldout", type=int, default=heldout, help="also this many held-out host photos (../shared)")
    p.add_argument("--views", type=int, default=5, help="held-out ground-truth views per e2e_psnr")


def _quick(p, **settings) -> None:
    """--quick: a smoke run of the benchmark with `settings` in place of the options given."""
    desc = ", ".join(f"--{k.replace('_', '-')} {v}" for k, v in settings.items())
    p.add_argument("--quick", action="store_true", help=f"a smoke run ({desc})" if desc else "a smoke run")
    run = p.get_default("func")
    p.set_defaults(func=lambda args: run(_resolved(args, settings)))


def _resolved(args, settings: dict):
    if args.quick:
        for k, v in settings.items():
            setattr(args, k, v)
    if args.out is None:
        args.out = "bench/results/quick" if args.quick else "bench/results"
    return args


def _capture_shape(p, size: int) -> None:
    """--size and --views of the synthetic captures (make-capture) that `bench capture-background` and `bench
    capture-chain` fit."""
    p.add_argument("--size", type=int, default=size, help="capture width in pixels (height 3/4 of it)")
    p.add_argument("--views", type=int, default=48, help="capture frames (every 8th held out)")


def _scene_sweep(p, scenes: str, scenes_help: str, hosts_help: str) -> None:
    """The options of a bench over scenes x hosts x simulated photos: --scenes, --hosts, --seeds, --size."""
    p.add_argument("--scenes", default=scenes, help=scenes_help)
    p.add_argument("--hosts", default="coffee,chelsea", help=hosts_help)
    p.add_argument("--seeds", type=int, default=3, help="simulated photos per physical severity")
    p.add_argument("--size", type=int, default=128, help="orbit view size for restore_psnr")


def _print_sweep(p, scenes_help: str, severities: str) -> None:
    """`_scene_sweep` over the print ladder's scenes, plus --heldout and --severities."""
    _scene_sweep(p, "bench/models/spot-print.s3d,bench/models/lego-print-auto.s3d", scenes_help, "bundled host photos")
    p.add_argument("--heldout", type=int, default=2, help="also this many held-out host photos (../shared)")
    p.add_argument("--severities", default=severities, help="comma-separated severities")


def add_commands(sub) -> None:
    """Add `bench` and every benchmark under it to the top-level subparsers `sub`. A benchmark is one block
    below: `add(bsub, NAME, HELP, _run(MODULE, FUNCTION))`, `_out(p)`, its options, then `_quick(p, ...)`
    with the settings of its smoke run."""
    b = add(sub, "bench", "benchmarks: write CSV, JSON and PNG charts under bench/results/", None)
    bsub = b.add_subparsers(dest="what", required=True, metavar="WHAT")
    bf = add(bsub, "fit", "field_psnr against scene_kb and fit time, spot and lego; training throughput",
             _run("snapshot3d.bench.capture_background", "bench_fit_command"))   # bench/fit.py's unless --captures
    _out(bf)
    _quick(bf)
    bf.add_argument("--captures", action="store_true", help="instead: issue 40's measures, bench capture-background "
                    "on spot and duck composites (no masks on white, with --background outer, masked)")
    bf.add_argument("--scenes", default="spot,lego", help="comma-separated bench scenes; a subset writes fit_<names>.*")
    bf.add_argument("--merge", action="store_true", help="only combine fit_<scene>.json files into fit.* (with "
                    "--representations: NAME_*.json into NAME.*)")
    bf.add_argument("--representations", action="store_true", help="instead: tri-planes against a dense grid, a hash "
                    "grid and a pure MLP at equal bytes (issue 37 item 2; writes fit_representations.*)")
    bf.add_argument("--budgets-kb", default="4,16,64,160", help="with --representations: the byte budgets (kB)")
    bf.add_argument("--kinds", default="triplane-shared,triplane,grid,hash,mlp",
                    help="with --representations: the representations")
    bf.add_argument("--rep-steps", type=int, default=1500, help="with --representations: fit steps")
    bf.add_argument("--rep-rays", type=int, default=4096, help="with --representations: rays per step")
    bf.add_argument("--rep-views", type=int, default=0, help="with --representations: held-out views scored (0: all)")
    bf.add_argument("--rep-name", default="fit_representations", help="with --representations: results file name")
    bf.add_argument("--device", default="auto", choices=("auto", "cpu", "cuda"),
                    help="with --representations: where the fits run")

    bg = add(bsub, "capture-background", "synthetic captures (make-capture) fitted without masks on white, without "
                                         "masks with --background outer, and with the true masks: the object's PSNR "
                                         "in its true mask and the density outside it (issue 40 item 2)",
             _run("snapshot3d.bench.capture_background", "bench_capture_background_command"))
    _out(bg)
    bg.add_argument("--meshes", default="spot", help="comma-separated built-in meshes")
    bg.add_argument("--modes", default="white,outer,masked", help="comma-separated fits: white, outer, masked, "
                    "masked-refine, outer-refine (with --refine-poses), and the candidates of docs/capture-record.md")
    _capture_shape(bg, size=128)
    bg.add_argument("--steps", type=int, default=300, help="fit steps")
    bg.add_argument("--occ-warmup", type=int, default=32, help="fit steps before the first occupancy update")
    bg.add_argument("--plane-res", type=int, default=64, help="plane resolution")
    bg.add_argument("--plane-channels", type=int, default=8, help="plane channels")
    bg.add_argument("--seed", type=int, default=0, help="capture and fit seed")
    bg.add_argument("--fit-seeds", default="", help="comma-separated fit seeds, each fitting every capture and mode "
                    "again (the fits' own spread; rows carry fit_seed); default: --seed")
    bg.add_argument("--pose-noise-deg", type=float, default=0.0, help="rms rotation error of the capture's written "
                    "poses (degrees; the fits are scored at the true poses)")
    bg.add_argument("--pose-noise-frac", type=float, default=0.0, help="rms position error of the written poses, a "
                    "fraction of the camera's distance")
    bg.add_argument("--arc-deg", type=float, default=720.0, help="degrees the capture's walk turns round the "
                    "object (720: two turns; 120: a frontal arc)")
    bg.add_argument("--name", default="capture_background", help="results file name (without .json/.csv)")
    bg.add_argument("--figure", action="store_true", help="also NAME_side_by_side_MESH.png of each mesh's outer "
                    "fits: held-out input photos, the fit with its background model, the object alone")
    _quick(bg, size=48, views=8, steps=20)

    bc = add(bsub, "capture-chain", "issue 40's chain on one synthetic capture: fit --budget auto --medium print, "
                                    "embed, sheet, simulate and decode; the object as fitted and as decoded scored "
                                    "against the capture's truth",
             _run("snapshot3d.bench.capture_chain", "bench_capture_chain_command"))
    _out(bc)
    bc.add_argument("--mesh", default="spot", help="built-in mesh the capture is made of")
    bc.add_argument("--modes", default="outer", help="comma-separated fits of bench capture-background (the photos' "
                    "fits: outer and its candidates), over the fit's defaults")
    _capture_shape(bc, size=160)
    bc.add_argument("--steps", type=int, default=400, help="fit steps per rung of the budget's ladder")
    bc.add_argument("--seed", type=int, default=0, help="capture seed")
    bc.add_argument("--fit-seed", type=int, default=0, help="fit seed")
    bc.add_argument("--severity", default="moderate", choices=SEVERITIES, help="simulate's severity")
    bc.add_argument("--photo-seeds", default="0,1,2", help="comma-separated simulate seeds, one photo each")
    bc.add_argument("--name", default="capture_chain", help="results file name (without .json/.csv)")
    bc.add_argument("--figure", action="store_true", help="also NAME_MODE_side_by_side.png: held-out frames, each "
                    "a row: the capture's photo, the object alone over white (the truth), the fitted scene and the "
                    "scene decoded from each photo")
    _quick(bc, size=48, views=8, steps=20, photo_seeds="0")

    bs = add(bsub, "capture-summary", "issue 40's targets by the medians over fit seeds, from bench "
                                      "capture-background results files (no fitting): per capture and "
                                      "--seen-ground-weight, the object's gap to the masked fit and the floaters",
             _run("snapshot3d.bench.capture_summary", "bench_capture_summary_command"))
    _out(bs)
    bs.add_argument("files", nargs="+", help="capture-background results (.json), the masked fits' among them")
    bs.add_argument("--name", default="capture_summary", help="results file name (without .json/.csv/.png)")

    bv = add(bsub, "serve", "snapshot3d serve under concurrent uploads (answers, latency, memory, /render) and the "
                            "page in headless Chromium (first view, frame rate, screenshots)",
             _run("snapshot3d.bench.serve", "bench_serve_command"))
    _out(bv)
    bv.add_argument("--uploads", type=int, default=100, help="uploads sent at once")
    bv.add_argument("--renders", type=int, default=50, help="/render requests timed one after another")
    bv.add_argument("--deadline-s", type=float, default=300.0, help="clients stop retrying after this")
    _quick(bv, uploads=6, renders=5)

    bz = add(bsub, "fuzz", "hostile inputs (issue 36) against the readers, the command lines and a live serve: "
                           "counts per class and outcome (tracebacks, 5xx, non-finite, partial output, memory)",
             _run("snapshot3d.bench.fuzz", "bench_fuzz_command"))
    _out(bz)
    bz.add_argument("--seed", type=int, default=36, help="seed of every mutation (the same seed, the same inputs)")
    bz.add_argument("--scale", type=float, default=1.0, help="multiplies the count of mutated inputs per class")
    bz.add_argument("--per-class", type=int, default=2, help="command lines per class also run as subprocesses")
    bz.add_argument("--workers", type=int, default=2, help="processes for the in-process inputs")
    _quick(bz)

    bp = add(bsub, "print-predict", "the print channel's model fitted on moderate captures, and its per-scene "
                                     "restore predictions against measured restores (writes the model to "
                                     "budget-curves.json)", _run("snapshot3d.bench.print_predict",
                                                                 "bench_print_predict_command"))
    _out(bp)
    bp.add_argument("--scenes", default="spot-r16c4,spot-r24c4,spot-r32c4,spot-r48c4,lego-print",
                    help="bench scenes (bench/models/NAME.s3d)")
    bp.add_argument("--hosts", default="coffee,chelsea", help="bundled host photos")
    bp.add_argument("--heldout", type=int, default=2, help="also this many held-out host photos (../shared)")
    bp.add_argument("--seeds", type=int, default=3, help="captures per scene and host")
    bp.add_argument("--draws", type=int, default=2, help="noise draws per host for a prediction")
    bp.add_argument("--severity", default="moderate", choices=SEVERITIES, help="capture severity")
    bp.add_argument("--size", type=int, default=128, help="view size for restore_psnr")
    _quick(bp, scenes="spot-r16c4,lego-print", hosts="chelsea", heldout=0, seeds=1, draws=1)

    bs = add(bsub, "scan", "scanner on simulated photos: detection, corner error, PSNR, speed; charts",
             _run("snapshot3d.bench.scan", "bench_scan_command"))
    _out(bs)
    bs.add_argument("--seeds", type=int, default=200, help="simulated photos per severity for mild and moderate")
    bs.add_argument("--severe-seeds", type=int, default=100, help="simulated severe photos")
    bs.add_argument("--negatives", type=int, default=50, help="photos with no sheet")
    bs.add_argument("--timing-runs", type=int, default=30, help="repeated scans of one 12 MP photo for the time median")
    _quick(bs, seeds=2, severe_seeds=2, negatives=2, timing_runs=2)

    bh = add(bsub, "channel", "what scan leaves of a printed snapshot, as the codec channel's parameters",
             _run("snapshot3d.bench.channel", "bench_channel_command"))
    _out(bh)
    bh.add_argument("--seeds", type=int, default=8, help="simulated photos per severity")
    bh.add_argument("--severities", default="jpeg75,mild,moderate,severe", help="comma-separated severities")
    bh.add_argument("--real", action="store_true", help="MTF, noise and tone of real photos of printed ArUco "
                    "boards beside simulated photos of the same boards per physical preset (--seeds each): "
                    "channel_real.{json,csv,png}")
    bh.add_argument("--photos", default=None, help="with --real: a folder of board photos "
                    "(default ../shared/data/photos/aruco)")
    _quick(bh, seeds=1)

    bg = add(bsub, "print-digital", "the print medium's digital payload candidate (quantised planes, CRC, "
                                     "convolutional code, nested layers) against the analog carriers on the same "
                                     "captures, and what an ideal code could carry",
             _run("snapshot3d.bench.print_digital", "bench_print_digital_command"))
    _out(bg)
    _print_sweep(bg, "comma-separated scene files (the print ladder's choices)", "none,jpeg75,mild,moderate,severe")
    bg.add_argument("--codes", default="conv,ldpc", help="comma-separated digital candidates: conv (convolutional "
                    "code, bit-planes), ldpc (IRA-LDPC layers, entropy-coded transform coder; needs the ldpc package)")
    _quick(bg, scenes="bench/models/spot-print.s3d", hosts="chelsea", heldout=0, seeds=1, severities="none,moderate")

    bb = add(bsub, "print-bands", "which bands a print and a phone keep per unit of host fidelity, and the print "
                                   "codec's candidate band sets through the real channel",
             _run("snapshot3d.bench.print_bands", "bench_print_bands_command"))
    _out(bb)
    _print_sweep(bb, "comma-separated scene files (the first also carries the all-band response rows)",
                 "jpeg75,mild,moderate,severe")
    bb.add_argument("--pools", default="", help="comma-separated band sets (default: all of bench.print_bands.CANDIDATES)")
    _quick(bb, scenes="bench/models/spot-print.s3d", hosts="chelsea", heldout=0, seeds=1, severities="moderate",
           pools="print-1,chroma-4px")

    bf = add(bsub, "fit-channel", "a fit's last phase through the print channel's model or through the 8-bit "
                                  "rounding only (paired, one shared prefix): field_psnr, and e2e_psnr through "
                                  "simulated prints", _run("snapshot3d.bench.fit_channel", "bench_fit_channel_command"))
    _out(bf)
    bf.add_argument("--scene", default="builtin:spot", help="scene to fit: builtin:NAME or posed images (a Blender "
                                                           "folder such as ../shared/data/scenes/lego_subset)")
    bf.add_argument("--downscale", type=int, default=4, help="posed images from files: divide their size by this")
    bf.add_argument("--plane-res", type=int, default=16, help="R of the planes (the print budget's choice for spot)")
    bf.add_argument("--plane-channels", type=int, default=4, help="C of the planes")
    bf.add_argument("--steps", type=int, default=1500, help="fit steps")
    bf.add_argument("--seed", type=int, default=0, help="fit seed")
    bf.add_argument("--size", type=int, default=200, help="view size of the scene's images")
    bf.add_argument("--hosts", default="coffee,chelsea", help="bundled host photos")
    bf.add_argument("--severities", default="moderate,mild", help="comma-separated physical severities")
    bf.add_argument("--seeds", type=int, default=6, help="simulated photos per severity and host")
    bf.add_argument("--views", type=int, default=10, help="held-out ground-truth views per e2e_psnr")
    bf.add_argument("--threads", type=int, default=2, help="torch threads of the fit, and photo worker processes")
    bf.add_argument("--cache", default=None, help="file caching the shared prefix of the fit (reused when present)")
    _quick(bf, steps=20, hosts="coffee", severities="moderate", seeds=1, views=2)

    bv = add(bsub, "decoders", "shared decoder versions through a print: e2e_psnr at held-out views of the same "
                               "scene fitted for each, per severity, paired by photo",
             _run("snapshot3d.bench.decoders", "bench_decoders_command"))
    _out(bv)
    bv.add_argument("--scenes", default="bench/models/spot-print.s3d,bench/models/spot-print-tri-dec-2.s3d,"
                                        "bench/models/lego-print-auto.s3d,bench/models/lego-print-tri-dec-2.s3d",
                    help="comma-separated scene files: one scene fitted for each decoder, named <scene>-...")
    _through_print_options(bv, seeds=3)
    bv.add_argument("--search", default="bench/results/decoder_search.jsonl",
                    help="rows of the decoder search (JSON lines) to chart beside (empty: none)")
    _quick(bv, scenes="bench/models/spot-print.s3d", hosts="coffee", heldout=0, severities="moderate", seeds=1,
           views=2, size=48, search="")

    be = add(bsub, "e2e", "what a print gives of a scene against the payload: e2e_psnr at held-out views per severity "
                          "for scenes fitted at several plane sizes, beside the field alone and the capacity bound; "
                          "a side-by-side per scene",
             _run("snapshot3d.bench.e2e", "bench_e2e_command"))
    _out(be)
    be.add_argument("--medium", default="print", choices=["print"], help="the medium (the print medium only)")
    be.add_argument("--scenes", default="bench/models/spot-print.s3d,bench/models/spot-r24c4.s3d,"
                                        "bench/models/spot-r32c4.s3d,bench/models/spot-r48c4.s3d,"
                                        "bench/models/lego-print-auto.s3d,bench/models/lego-print.s3d",
                    help="comma-separated scene files named <scene>-...; the first of each scene is the side-by-side's")
    _through_print_options(be, seeds=6)
    _quick(be, scenes="bench/models/spot-print.s3d", hosts="coffee", heldout=0, severities="moderate", seeds=1,
           views=2, size=48)

    bb = add(bsub, "burst", "several photos of one print against one: e2e_psnr of each photo alone, the best by the "
                            "pilots, the captures' mean and their pilot-weighted mean (what decode does with several)",
             _run("snapshot3d.bench.burst", "bench_burst_command"))
    _print_scene_options(bb, heldout=2)
    bb.add_argument("--severities", default="mild,moderate,severe", help="comma-separated physical severities")
    bb.add_argument("--prints", type=int, default=2, help="prints per host and severity")
    bb.add_argument("--photos", type=int, default=4, help="photos per print (2 to 8)")
    _quick(bb, hosts="coffee", heldout=0, severities="moderate", prints=1, photos=2, views=1)

    ba = add(bsub, "print-ablation", "where a physical severity's error comes from: each photo again with one knob of its "
                                     "preset at its ideal (light, halftone, printer, tilt, blur, sensor, JPEG, white "
                                     "balance; the print alone, the camera alone) and with an oracle flat field; paired "
                                     "gains in restore and e2e",
             _run("snapshot3d.bench.print_ablation", "bench_print_ablation_command"))
    _print_scene_options(ba, heldout=0)
    ba.add_argument("--severity", default="moderate", help="one physical severity")
    ba.add_argument("--seeds", type=int, default=6, help="photos per host")
    ba.add_argument("--size", type=int, default=96, help="orbit view size for restore_psnr")
    _quick(ba, hosts="coffee", heldout=0, seeds=1, views=1, size=48)

    bs = add(bsub, "decoder-search", "candidate shared decoders scored by what they fit: spot and lego at small "
                                     "plane sizes, field_psnr clean and with plane noise (JSON lines; for a GPU)",
             _run("snapshot3d.bench.decoder_search", "bench_decoder_search_command"))
    bs.add_argument("--decoders", default="tri-dec-1,tri-dec-2",
                    help="comma-separated shipped versions or weights files from 'train decoder -o FILE'")
    bs.add_argument("--sizes", default="16x4,32x4", help="comma-separated plane sizes RxC")
    bs.add_argument("--steps", type=int, default=1500, help="fit steps")
    bs.add_argument("--noise", type=float, default=0.05, help="std of the plane noise of field_psnr_noise")
    bs.add_argument("--device", default="auto", choices=("auto", "cpu", "cuda"), help="where the fits run")
    bs.add_argument("--out-file", default="bench/results/decoder_search.jsonl", help="JSON lines appended to")

    bc = add(bsub, "codec", "a medium's codec: host fidelity vs restore_psnr through simulate+scan; baselines; "
                            "charts (codec.* for the file medium, codec_print.* for the print medium)",
             _run("snapshot3d.bench.codec", "bench_codec_command"))
    _out(bc)
    bc.add_argument("--medium", default="file", choices=MEDIA, help="which medium's codec to measure")
    bc.add_argument("--scenes", default=None,
                    help="comma-separated scene files to evaluate (spot is never trained on; default: file "
                         "snapshot3d/assets/spot.s3d,cache/scenes/lego.s3d; print bench/models/spot-print.s3d,"
                         "bench/models/lego-print-auto.s3d, the print ladder's choices)")
    bc.add_argument("--hosts", default="coffee,chelsea", help="bundled host photos (held out from training)")
    bc.add_argument("--headline", default="spot,lego", help="scenes (file stems) the summary's medians are over")
    bc.add_argument("--seeds", type=int, default=None, help="simulated photos per physical severity (default: file 3, "
                                                             "print 6)")
    bc.add_argument("--size", type=int, default=128, help="orbit view size for restore_psnr")
    bc.add_argument("--refine", type=int, default=FILE_REFINE_STEPS, help="embed-time refinement steps of the ours-refined rows "
                                                           "and the side-by-side figure (0: neither)")
    bc.add_argument("--strengths", default=None, help="embedding strengths of the trade-off sweep (default: file "
                                                      "0.5,0.75,1,1.5,2; print 0.5,0.71,1,1.41,2)")
    bc.add_argument("--digital", default="bench/models/codec-digital.npz",
                    help="file medium, baseline a: the codec trained without the channel")
    bc.add_argument("--heldout", type=int, default=4, help="print medium: photos of ../shared/data/hosts/heldout "
                                                           "added to --hosts (0: none)")
    bc.add_argument("--methods", default="print,print-front,file",
                    help="print medium: rows to measure (print: the codec as decode runs it; print-front: a learned front-end before its despreader; "
                         "file: the file codec on print captures)")
    bc.add_argument("--payloads", default="bench/models/spot-r16c4.s3d,bench/models/spot-r24c4.s3d,"
                                          "bench/models/spot-r32c4.s3d,bench/models/spot-r48c4.s3d,snapshot3d/assets/spot.s3d",
                    help="print medium: spot at other plane sizes for the payload sweep")
    _quick(bc, scenes=None, hosts="coffee", seeds=1, size=48, refine=5, strengths="1", heldout=0,
           payloads="bench/models/spot-r32c4.s3d")

    bj = add(bsub, "codec-jpeg", "a snapshot file shared: metadata from the pixels and restore_psnr through JPEG, "
                                 "resizing and crops; and the codec alone through JPEG (4:2:0, 4:4:4), chroma "
                                 "subsampling, noise, blur and sub-pixel shifts, one at a time",
             _run("snapshot3d.bench.codec_jpeg", "bench_codec_jpeg_command"))
    _out(bj)
    bj.add_argument("--compare", default=None, help="another codec weights file measured beside the shipped one")
    bj.add_argument("--refine", type=int, default=FILE_REFINE_STEPS, help="also the shipped codec's snapshots refined this many "
                                                           "steps at embed time (0: not); the sharing part's snapshots "
                                                           "are refined this many steps")
    bj.add_argument("--part", default="all", choices=("all", "sharing", "distortions"),
                    help="sharing: shared copies of a file snapshot end to end (metadata from the pixels, JPEG, "
                         "resizing, crops; codec_sharing.*); distortions: the codec alone (codec_jpeg.*)")
    bj.add_argument("--hosts", default="coffee,chelsea", help="sharing part: bundled host photos")
    bj.add_argument("--heldout", type=int, default=2, help="sharing part: photos of ../shared/data/hosts/heldout too")
    bj.add_argument("--scenes", default="bench/models/lego-print.s3d",
                    help="sharing part: scene files beside the bundled spot (comma-separated)")
    _quick(bj, refine=5, hosts="coffee", heldout=0, scenes="")

    br = add(bsub, "refine", "embed-time refinement of file snapshots: restore_psnr of the PNG, a JPEG-75 and a 256-px "
                             "copy (read with no text) against refinement time, per schedule and step count",
             _run("snapshot3d.bench.refine", "bench_refine_command"))
    _out(br)
    br.add_argument("--steps", default="0,20,40,50,70,100,140", help="step counts of the shipped schedule (turns)")
    br.add_argument("--former", type=int, default=100, help="steps of the former schedule (both copies every step, "
                                                            "host weighted) measured beside it (0: not)")
    br.add_argument("--scenes", default="snapshot3d/assets/spot.s3d,bench/models/lego-print.s3d",
                    help="comma-separated scene files")
    br.add_argument("--hosts", default="coffee", help="bundled host photos")
    br.add_argument("--heldout", type=int, default=1, help="also this many held-out host photos (../shared)")
    br.add_argument("--strengths", default="1",
                    help="embed strengths or host PSNRs (comma-separated, like 0.55,38dB: `embed --strength` or "
                         "`--host-psnr`); each besides 1 adds the network's snapshot and one refined with "
                         "--strength-steps at that setting: restore_psnr against host_psnr")
    br.add_argument("--strength-steps", type=int, default=FILE_REFINE_STEPS,
                    help="refinement steps of the strength sweep (default: embed's)")
    _quick(br, steps="0,2", former=2, hosts="coffee", heldout=0, scenes="snapshot3d/assets/spot.s3d",
           strengths="1,38dB", strength_steps=2)

    bq = add(bsub, "capacity", "the capture channel's Gaussian capacity per severity and the best restore_psnr "
                               "it allows, beside the shipped codec's, per plane size",
             _run("snapshot3d.bench.capacity", "bench_capacity_command"))
    _out(bq)
    _scene_sweep(bq, "snapshot3d/assets/spot.s3d,bench/models/spot-r48c4.s3d,bench/models/spot-r32c4.s3d",
                 "comma-separated scene files (spot fitted at several plane sizes)",
                 "bundled host photos (held out from training)")
    _quick(bq, scenes="snapshot3d/assets/spot.s3d", hosts="coffee", seeds=1, size=48)

    bqe = add(bsub, "quality", "the print decode's expected restore quality against the measured one, on scenes and "
                               "plane sizes held out of its calibration; writes the calibration decode reads",
              _run("snapshot3d.bench.quality", "bench_quality_command"))
    _out(bqe)
    bqe.add_argument("--fit-scenes", default="bench/models/spot-print.s3d,bench/models/lego-print.s3d",
                     help="scenes the line is fitted on (photos in the calibration hosts)")
    bqe.add_argument("--check-scenes", default="bench/models/lego-print-auto.s3d,bench/models/spot-r24c4.s3d,"
                                               "bench/models/spot-r32c4.s3d,bench/models/spot-r48c4.s3d",
                     help="scenes held out of the fit (photos in the held-out hosts)")
    bqe.add_argument("--seeds", type=int, default=4, help="photos per scene, host and physical severity (a digital capture, jpeg90 or jpeg75, is one photo at any seed)")
    bqe.add_argument("--calibration-dir", default=None,
                     help="where to write the line (default: the package's assets, which decode reads)")
    _quick(bqe, seeds=1, fit_scenes="bench/models/spot-print.s3d", check_scenes="bench/models/lego-print-auto.s3d",
           calibration_dir="bench/results/quick")

    bd = add(bsub, "decode", "torch-free decode of simulated photos: decode_ms per stage, restore_psnr, e2e_psnr; "
                             "a speed/accuracy sweep and its chart; each codec's quality estimate calibrated",
             _run("snapshot3d.bench.decode", "bench_decode_command"))
    _out(bd)
    bd.add_argument("--scene", default="snapshot3d/assets/spot-print.s3d", help="scene of the end-to-end photos "
                                                                                 "and the sweep (print medium)")
    bd.add_argument("--seeds", type=int, default=20, help="simulated photos")
    bd.add_argument("--severity", default="moderate", choices=SEVERITIES, help="simulated print-and-capture severity")
    bd.add_argument("--host", default="chelsea", help="bundled host photo (held out from codec training)")
    bd.add_argument("--sweep-severity", default="moderate", choices=SEVERITIES, help="capture the settings sweep runs on")
    bd.add_argument("--repeats", type=int, default=3, help="timed decodes per sweep setting (median)")
    bd.add_argument("--calib-scenes", default="bench/models/spot-print.s3d,bench/models/lego-print.s3d",
                    help="scenes of the quality estimate's calibration captures")
    bd.add_argument("--calib-seeds", type=int, default=3, help="captures per severity, scene and host for the "
                                                               "quality estimate's lines")
    bd.add_argument("--calibration-dir", default=None,
                    help="where to write the lines (default: the package's assets, which decode reads)")
    bd.add_argument("--profile", action="store_true",
                    help="only profile the decode of the example photo: each stage's median time and share over "
                         "--repeats decodes, and cProfile's top functions (decode_profile.{json,txt})")
    bd.add_argument("--cold", type=int, default=3, help="with --profile: also time this many decodes, each by "
                                                        "`snapshot3d decode` in a fresh process (decode_profile.png)")
    _quick(bd, seeds=2, repeats=1, calib_seeds=1, calib_scenes="bench/models/spot-print.s3d",
           calibration_dir="bench/results/quick")

    bc = add(bsub, "calibrate", "calibrate on simulated photos of the chart: MTF50, gain and nearest preset against "
                                "the simulator's own values (issue 38 targets)",
             _run("snapshot3d.bench.calibrate", "bench_calibrate_command"))
    _out(bc)
    bc.add_argument("--seeds", type=int, default=6, help="photos per physical preset")
    bc.add_argument("--pilots", action="store_true", help="also compare the band gains and noise with what the print "
                                                          "codec's carriers (and pilots) read on flat grey "
                                                          "photographed with the same seed")
    bc.add_argument("--draws", type=int, default=8, help="with --pilots: draws of the codec's planes averaged in the "
                                                        "reference (its standard error goes in the CSV)")
    bc.add_argument("--reference", action="store_true", help="print the presets' reference table "
                                                             "(scanner.calibrate.PRESET_REFERENCE) from seeds 100-111")
    _quick(bc, seeds=1)

    bh = add(bsub, "decode-channel", "the channel report of print decodes (gain, noise, SNR, nearest preset, advice) "
                                     "on simulated photos; restore_psnr beside its estimate (issue 38 item 4)",
             _run("snapshot3d.bench.decode_channel", "bench_decode_channel_command"))
    _out(bh)
    bh.add_argument("--scenes", default="snapshot3d/assets/spot-print.s3d,bench/models/lego-print-auto.s3d",
                    help="comma-separated print scene files")
    bh.add_argument("--hosts", default="coffee,chelsea", help="comma-separated bundled host photos")
    bh.add_argument("--seeds", type=int, default=3, help="photos per physical preset, scene and host (seeds 0..N-1)")
    bh.add_argument("--size", type=int, default=128, help="orbit view size for restore_psnr")
    bh.add_argument("--reference", action="store_true", help="print viewer.channel.CHANNEL_REFERENCE from seeds "
                                                             "100-105 instead of scoring")
    _quick(bh, seeds=1, hosts="chelsea")
