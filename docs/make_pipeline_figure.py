"""Make docs/pipeline.png, the README's picture, from the product's own outputs.

It runs the real commands in a temporary folder (embed the bundled spot scene in the bundled host photo
chelsea, print it as a sheet, photograph the sheet with the `moderate` simulator, decode the photo), then
puts four panels side by side: the snapshot, the printed sheet, the phone photo, and four of the decoded
views turned around the scene.

    python docs/make_pipeline_figure.py            # writes docs/pipeline.png (about 200 kB)
"""
from __future__ import annotations

import subprocess
import sys
import tempfile
from pathlib import Path

from PIL import Image, ImageDraw, ImageFont

ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / "snapshot3d" / "assets" / "spot-print.s3d"
PANEL_H = 300          # every panel is scaled to this height (pixels)
GAP, LABEL_H = 12, 28  # space between panels, height of the caption strip
VIEWS = (0, 5, 10, 15)  # of the 20 orbit views: a quarter turn apart


def run(*args: str, cwd: Path) -> None:
    """One snapshot3d command, as a user types it (stops the script on failure)."""
    subprocess.run([sys.executable, "-m", "snapshot3d", *args], cwd=cwd, check=True)


def make_outputs(work: Path) -> dict[str, Path]:
    run("embed", str(SCENE), "--host", "builtin:chelsea", "-o", "snap.png", cwd=work)
    run("sheet", "snap.png", "-o", "sheet.pdf", cwd=work)
    run("simulate", "sheet.png", "-o", "photo.jpg", "--severity", "moderate", "--seed", "0", cwd=work)
    run("decode", "photo.jpg", "-o", "out", cwd=work)
    return {"snapshot": work / "snap.png", "sheet": work / "sheet.png", "photo": work / "photo.jpg",
            "views": work / "out" / "views"}


def scaled(img: Image.Image, height: int) -> Image.Image:
    return img.convert("RGB").resize((round(img.width * height / img.height), height), Image.LANCZOS)


def views_panel(folder: Path) -> Image.Image:
    """Four decoded views in a 2x2 grid, PANEL_H high."""
    half = PANEL_H // 2
    tiles = [scaled(Image.open(folder / f"{i:03d}.png"), half) for i in VIEWS]
    grid = Image.new("RGB", (2 * tiles[0].width, PANEL_H), "white")
    for k, t in enumerate(tiles):
        grid.paste(t, ((k % 2) * t.width, (k // 2) * half))
    return grid


def compose(files: dict[str, Path], out: Path) -> None:
    panels = [("1. snapshot (embed)", scaled(Image.open(files["snapshot"]), PANEL_H)),
              ("2. printed sheet (sheet)", scaled(Image.open(files["sheet"]), PANEL_H)),
              ("3. phone photo (simulate)", scaled(Image.open(files["photo"]), PANEL_H)),
              ("4. turned views (decode)", views_panel(files["views"]))]
    width = sum(p.width for _, p in panels) + GAP * (len(panels) + 1)
    fig = Image.new("RGB", (width, PANEL_H + LABEL_H + 2 * GAP), "white")
    draw = ImageDraw.Draw(fig)
    try:
        font = ImageFont.truetype("DejaVuSans.ttf", 16)
    except OSError:
        font = ImageFont.load_default()
    x = GAP
    for label, panel in panels:
        fig.paste(panel, (x, GAP))
        draw.text((x, GAP + PANEL_H + 6), label, fill="black", font=font)
        x += panel.width + GAP
    # 256 colours with dithering keep the file near 200 kB (the full-colour PNG is about 580 kB)
    fig.quantize(colors=256, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.FLOYDSTEINBERG).save(
        out, optimize=True)


def main() -> int:
    out = ROOT / "docs" / "pipeline.png"
    with tempfile.TemporaryDirectory() as tmp:
        compose(make_outputs(Path(tmp)), out)
    print(f"wrote {out} ({out.stat().st_size // 1024} kB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
