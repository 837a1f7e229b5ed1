"""The print-and-capture channel's severity presets (DESIGN section 3), each written down in full.

Ranges (lo, hi) are sampled uniformly per photo from the seed. Values are physical where they can
be: reflectances in [0, 1] (linear light), angles in degrees, blur and noise in photo pixels and in
units of the sensor's full scale. `none`, `jpeg90` and `jpeg75` are digital channels: the sheet image
itself, losslessly or JPEG-compressed, with no printer, scene or camera."""
from __future__ import annotations

from dataclasses import asdict, dataclass

from snapshot3d import formats

__all__ = ["Preset", "PRESETS", "SEVERITIES", "get_preset", "PRINTER_DPI", "print_dots"]

PRINTER_DPI = 600
"""the simulated printer's resolution; a sheet's printed size sets its dots per snapshot pixel"""


def print_dots(width_mm: float) -> int:
    """Printer dots per snapshot pixel for a sheet printed `width_mm` wide at PRINTER_DPI (the presets'
    4 is a sheet of about 100 mm)."""
    from . import layout
    return max(1, round(width_mm / 25.4 * PRINTER_DPI / layout.sheet_size()[0]))


@dataclass(frozen=True)
class Preset:
    """One severity of the print-and-capture channel."""

    name: str
    physical: bool = True
    """False: a digital channel (no print, no camera); only `jpeg_quality` applies"""
    # --- printer ---
    tone_gamma: float = 1.0
    """printer tone curve (dot gain): printed linear value = digital linear value ** tone_gamma"""
    gamut: float = 1.0
    """saturation the printer keeps: colours are pulled toward their own grey by (1 - gamut)"""
    ink_black: float = 0.0
    """linear reflectance of solid black ink, relative to the paper"""
    paper_white: tuple = (1.0, 1.0, 1.0)
    """linear RGB reflectance of the paper"""
    halftone: bool = False
    """ordered-dither halftoning (4x4 Bayer, one screen phase per ink) at the printer's dot resolution"""
    print_dots_per_px: int = 4
    """printer dots per snapshot pixel (4 = about 600 dpi for a 100 mm sheet)"""
    paper_texture: float = 0.0
    """std of the paper's multiplicative fibre texture"""
    # --- pose and lens ---
    tilt_deg: tuple = (0.0, 0.0)
    """angle between the sheet's normal and the camera's axis"""
    coverage: tuple = (0.10, 0.60)
    """snapshot area / frame area (the upper end shrinks where the sheet would not fit the frame)"""
    focal_frac: tuple = (0.72, 0.80)
    """focal length / frame width (a phone's main camera: about 26 mm equivalent)"""
    k1: tuple = (0.0, 0.0)
    """radial distortion x_d = x_u (1 + k1 r^2), r in focal lengths"""
    # --- scene light ---
    exposure: tuple = (0.85, 1.0)
    """sensor value of white paper under the brightest light"""
    gradient: tuple = (0.0, 0.0)
    """illumination fall-off across the frame (fraction of the brightest)"""
    shadow: tuple = (0.0, 0.0)
    """darkening inside a soft-edged shadow crossing the sheet"""
    glare: tuple = (0.0, 0.0)
    """peak of an additive specular spot on the sheet (fraction of full scale)"""
    # --- camera ---
    defocus_px: tuple = (0.0, 0.0)
    """radius of the defocus disk"""
    motion_px: tuple = (0.0, 0.0)
    """length of the straight motion-blur path"""
    noise_shot: tuple = (0.0, 0.0)
    """Poisson part: noise variance per unit of signal (full scale 1)"""
    noise_read: tuple = (0.0, 0.0)
    """Gaussian read-noise std (full scale 1)"""
    white_balance: float = 0.0
    """max relative error of each channel's white-balance gain"""
    jpeg_quality: tuple = (95, 95)
    """JPEG quality of the saved photo; 0 = lossless PNG"""
    frame: tuple = (4000, 3000)
    """photo width, height (12 MP)"""

    def as_dict(self) -> dict:
        return asdict(self)


PRESETS = {
    "none": Preset("none", physical=False, jpeg_quality=(0, 0)),
    "jpeg90": Preset("jpeg90", physical=False, jpeg_quality=(90, 90)),
    "jpeg75": Preset("jpeg75", physical=False, jpeg_quality=(75, 75)),
    # A good inkjet on matte photo paper, the phone held steady and nearly square, daylight.
    "mild": Preset("mild", tone_gamma=1.08, gamut=0.92, ink_black=0.04, paper_white=(0.90, 0.89, 0.86), halftone=True,
                   paper_texture=0.01, tilt_deg=(0.0, 25.0), k1=(-0.02, 0.02), exposure=(0.85, 1.0),
                   gradient=(0.0, 0.15), shadow=(0.0, 0.1), glare=(0.0, 0.0), defocus_px=(0.0, 1.0),
                   motion_px=(0.0, 1.0), noise_shot=(0.0002, 0.0006), noise_read=(0.001, 0.002),
                   white_balance=0.03, jpeg_quality=(90, 95)),
    # An office printer on plain paper, a desk lamp to one side, hand-held at an angle.
    "moderate": Preset("moderate", tone_gamma=1.18, gamut=0.82, ink_black=0.08, paper_white=(0.86, 0.85, 0.80),
                       halftone=True, paper_texture=0.02, tilt_deg=(0.0, 45.0), k1=(-0.05, 0.05),
                       exposure=(0.7, 1.0), gradient=(0.1, 0.35), shadow=(0.0, 0.3), glare=(0.0, 0.25),
                       defocus_px=(0.5, 2.0), motion_px=(0.0, 3.0), noise_shot=(0.0006, 0.002),
                       noise_read=(0.002, 0.005), white_balance=0.08, jpeg_quality=(80, 92)),
    # A worn printer, dim uneven light with a hard lamp reflection, a steep hurried shot.
    "severe": Preset("severe", tone_gamma=1.3, gamut=0.7, ink_black=0.12, paper_white=(0.82, 0.80, 0.72), halftone=True,
                     paper_texture=0.03, tilt_deg=(0.0, 60.0), k1=(-0.1, 0.1), exposure=(0.45, 0.9),
                     gradient=(0.2, 0.5), shadow=(0.1, 0.5), glare=(0.1, 0.6), defocus_px=(1.0, 4.0),
                     motion_px=(0.0, 8.0), noise_shot=(0.002, 0.006), noise_read=(0.004, 0.01),
                     white_balance=0.15, jpeg_quality=(65, 82)),
}
SEVERITIES = formats.SEVERITIES
"""the severity names, mildest first (one preset each in `PRESETS`)"""


def get_preset(name) -> Preset:
    """A preset by name (or a `Preset`, returned as is, e.g. one changed with `dataclasses.replace`)."""
    if isinstance(name, Preset):
        return name
    if name not in PRESETS:
        raise ValueError(f"unknown severity {name!r}; choose from {', '.join(SEVERITIES)}")
    return PRESETS[name]
