"""The command line: one-line errors and non-zero exits for a user's mistakes; a real end-to-end run."""
import json
import subprocess
import sys

import numpy as np
import pytest

from snapshot3d import formats
from snapshot3d.scene import Orbit, Scene, save_scene


def run(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "snapshot3d", *args], capture_output=True, text=True, cwd=cwd,
                          timeout=600)


def _assert_one_line_error(proc, match):
    assert proc.returncode != 0
    err = proc.stderr.strip()
    assert "Traceback" not in err and len(err.splitlines()) == 1, err
    assert match in err, err


def test_fit_missing_path(tmp_path):
    proc = run("fit", str(tmp_path / "nope"), "-o", str(tmp_path / "x.s3d"))
    _assert_one_line_error(proc, "scene not found")
    assert not (tmp_path / "x.s3d").exists()


def test_fit_malformed_transforms(tmp_path):
    (tmp_path / "scene").mkdir()
    (tmp_path / "scene" / "transforms.json").write_text('{"frames": [ {"file_path": ')
    proc = run("fit", str(tmp_path / "scene"), "-o", str(tmp_path / "x.s3d"))
    _assert_one_line_error(proc, "not valid JSON")


def test_fit_unknown_builtin(tmp_path):
    _assert_one_line_error(run("fit", "builtin:nothing", "-o", str(tmp_path / "x.s3d")), "builtin")


@pytest.mark.parametrize("args,match", [
    (["--plane-channels", "20"], "--plane-channels must be in 1..12"),
    (["--steps", "0"], "--steps must be >= 1, not 0"),
    (["--ending", "channel"], "--ending must be auto or plain, not 'channel'"),
    (["--downscale", "0"], "--downscale must be >= 1"),
])
def test_fit_bad_settings(tmp_path, args, match):
    _assert_one_line_error(run("fit", "builtin:procedural", "-o", str(tmp_path / "x.s3d"), *args), match)
    assert not (tmp_path / "x.s3d").exists()


def test_render_scene_from_other_decoder(tmp_path):
    s = Scene(codes=np.zeros((3, 4, 8, 8), np.uint8), box=np.array([[-1, -1, -1], [1, 1, 1]]),
              orbit=Orbit(radius=3.0), decoder_version="tri-dec-0")
    save_scene(s, tmp_path / "old.s3d")
    proc = run("render", str(tmp_path / "old.s3d"), "-o", str(tmp_path / "views"))
    _assert_one_line_error(proc, "fitted for decoder 'tri-dec-0'")
    assert not (tmp_path / "views").exists()
    proc = run("mesh", str(tmp_path / "old.s3d"), "-o", str(tmp_path / "m.glb"))
    _assert_one_line_error(proc, "fitted for decoder")
    proc = run("fit", str(tmp_path / "old.s3d"), "-o", str(tmp_path / "new.s3d"))
    _assert_one_line_error(proc, "fitted for decoder 'tri-dec-0'")
    assert not (tmp_path / "new.s3d").exists()


def test_render_corrupt_scene(tmp_path):
    (tmp_path / "bad.s3d").write_text("hello")
    _assert_one_line_error(run("render", str(tmp_path / "bad.s3d"), "-o", str(tmp_path / "v")), "not a snapshot3d scene")


def test_fit_render_mesh_end_to_end(tmp_path):
    """A short real fit of the shipped default, then render and mesh from the written scene file."""
    out = tmp_path / "p.s3d"
    proc = run("fit", "builtin:procedural", "-o", str(out), "--size", "64", "--steps", "60", "--plane-res", "32",
               "--plane-channels", "4", "--occ-warmup", "20", "--report", str(tmp_path / "fit.json"))
    assert proc.returncode == 0, proc.stderr
    rep = json.loads((tmp_path / "fit.json").read_text())
    assert set(rep) == {"field_psnr", "field_ssim", "scene_kb", "fit_seconds", "steps", "plane_res", "plane_channels",
                        "head"}
    assert rep["head"] == "the shared decoder's"   # no --medium print: --head auto leaves the shared head
    assert rep["plane_res"] == 32 and rep["plane_channels"] == 4 and rep["steps"] == 60
    assert rep["field_psnr"] > 18.0 and abs(rep["scene_kb"] - (3 * 4 * 32 * 32 + 36) / formats.KB) < 0.01
    proc = run("render", str(out), "-o", str(tmp_path / "r"), "--views", "3", "--size", "48")
    assert proc.returncode == 0, proc.stderr
    assert sorted(p.name for p in (tmp_path / "r").iterdir()) == ["contact.png", "turntable.gif", "views"]
    assert sorted(p.name for p in (tmp_path / "r" / "views").iterdir()) == ["000.png", "001.png", "002.png"]
    proc = run("mesh", str(out), "-o", str(tmp_path / "m.ply"), "--res", "48")
    assert proc.returncode == 0, proc.stderr
    import trimesh
    mesh = trimesh.load(tmp_path / "m.ply")
    assert len(mesh.faces) > 100
    assert np.all(mesh.bounds[0] >= rep_box(out)[0] - 1e-4) and np.all(mesh.bounds[1] <= rep_box(out)[1] + 1e-4)


def rep_box(path):
    from snapshot3d.scene import load_scene_file
    return load_scene_file(path).box


def test_version_and_help_show_every_default():
    """`--version`; every option of every command has help, and help shows the default where there is one."""
    import argparse

    from snapshot3d import __version__
    from snapshot3d.cli import build_parser

    proc = run("--version")
    assert proc.returncode == 0 and proc.stdout.strip() == f"snapshot3d {__version__}"
    parser = build_parser()
    missing, commands = [], 0

    def walk(p, path):
        nonlocal commands
        for action in p._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name, sub in action.choices.items():
                    walk(sub, f"{path} {name}")
            elif action.option_strings and action.dest not in ("help", "version"):
                text = p.formatter_class(path)._get_help_string(action) or ""
                if not text.strip() or (action.default not in (None, False) and "%(default)" not in text):
                    missing.append(f"{path} {action.option_strings[-1]}")
        commands += 1
    walk(parser, "snapshot3d")
    assert commands > 20 and not missing, missing
    embed_help = build_parser().parse_args(["embed", "x.s3d", "-o", "y.png"])  # parses; hosts listed in help
    assert embed_help.host == "builtin:coffee"
    proc = run("embed", "--help")
    assert "builtin:NAME" in proc.stdout and "chelsea" in proc.stdout and f"(default: {formats.FILE_REFINE_STEPS})" in proc.stdout


def test_export_and_make_example_need_a_destination(tmp_path):
    """They never overwrite the shipped assets unless told to (--install)."""
    for cmd in ("export", "make-example"):
        proc = run(cmd)
        assert proc.returncode == 2 and "one of the arguments -o/--output --install is required" in proc.stderr
        proc = run(cmd, "-o", str(tmp_path / "x"), "--install")
        assert proc.returncode == 2 and "not allowed with argument" in proc.stderr


def test_plain_fit_says_what_to_run_for_a_print_and_fits_for_the_decoder_asked(tmp_path):
    """Plain `fit` writes 64x8 planes, more than a print carries well: one line says what to run instead (a
    snapshot is printed unless embedded as a file). `--decoder tri-dec-2` writes a scene of that decoder; an
    unknown decoder is refused in one line."""
    from snapshot3d.scene import load_scene_file
    proc = run("fit", "builtin:procedural", "-o", str(tmp_path / "a.s3d"), "--size", "32", "--steps", "3",
               "--occ-warmup", "1")
    assert proc.returncode == 0, proc.stderr
    hints = [ln for ln in proc.stdout.splitlines() if ln.startswith("hint:")]
    assert len(hints) == 1 and "64x8 planes" in hints[0] and "--budget auto --medium print" in hints[0], proc.stdout
    assert load_scene_file(tmp_path / "a.s3d").decoder_version == formats.DECODER_VERSION
    proc = run("fit", "builtin:procedural", "-o", str(tmp_path / "b.s3d"), "--size", "32", "--steps", "3",
               "--occ-warmup", "1", "--plane-res", "16", "--plane-channels", "4", "--decoder", "tri-dec-2")
    assert proc.returncode == 0, proc.stderr
    assert "hint:" not in proc.stdout and load_scene_file(tmp_path / "b.s3d").decoder_version == "tri-dec-2"
    _assert_one_line_error(run("fit", "builtin:procedural", "-o", str(tmp_path / "c.s3d"), "--decoder", "tri-dec-9"),
                           "--decoder must be one of tri-dec-1, tri-dec-2")
