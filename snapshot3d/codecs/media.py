"""The two media a snapshot travels through, written once (no numpy; torch-free): for each, the codec
`embed` writes, the codecs this build reads, how many plane channels and what plane sizes it carries and
how a snapshot file is written. `embed`, `restore`, `decode`, `serve`, `export` and the benches pick the
medium here (`medium_of` for a snapshot's codec id, `MEDIA[name]` for a medium named on the command line);
the codec ids themselves are `snapshot3d.formats`' constants.

The per-medium work lives beside each side: restoring in `viewer.media` (torch-free), embedding in
`train.codec.embedding` (torch), each a dict medium name -> function."""
from __future__ import annotations

from dataclasses import dataclass

from snapshot3d import formats
from snapshot3d.errors import UserError

__all__ = ["Medium", "MEDIA", "PRINT", "FILE", "CODEC_MEDIUM", "medium_of"]


@dataclass(frozen=True)
class Medium:
    """One medium and its codecs."""

    name: str
    """"print" or "file" (`formats.MEDIA`)"""
    codec: str
    """id of the codec `embed` writes"""
    codecs: tuple[str, ...]
    """ids of the codecs this build reads, newest first"""
    channels: tuple[int, int]
    """the fewest and most plane channels C it carries"""
    res: tuple[int, int]
    """the smallest and largest plane resolution R it carries"""
    file_scale: int
    """a snapshot file is written with each snapshot pixel a square of file_scale^2 pixels"""
    refusal: str
    """the one-line reason for planes it cannot carry (format fields: c, r, c0, c1, r0, r1)"""

    def plane_error(self, channels: int, res: int) -> str | None:
        """Why this medium cannot carry (3, channels, res, res) planes, or None when it can."""
        (c0, c1), (r0, r1) = self.channels, self.res
        if c0 <= channels <= c1 and r0 <= res <= r1:
            return None
        return self.refusal.format(c=channels, r=res, c0=c0, c1=c1, r0=r0, r1=r1)

    def check_planes(self, channels: int, res: int) -> None:
        """UserError naming the medium and the range it carries, unless it carries (3, channels, res, res)."""
        error = self.plane_error(channels, res)
        if error:
            raise UserError(f"{error} (medium {self.name})")


PRINT = Medium("print", formats.PRINT_CODEC, formats.PRINT_CODECS, (1, formats.C_MAX), (4, formats.CODEC_MAX_RES), 1,
               "the print codec carries planes of {r0}x{r0} to {r1}x{r1} with {c0} to {c1} channels; "
               "this scene has {c} channels of {r}x{r}")
FILE = Medium("file", formats.FILE_CODEC, formats.FILE_CODECS, (1, formats.CODEC_CHANNELS), (2, formats.CODEC_MAX_RES),
              formats.FILE_SCALE, "the codec carries planes of at most {c1} channels and {r1}x{r1}; this scene has {c} "
              "channels of {r}x{r} (refit with --plane-channels {c1})")
MEDIA = {m.name: m for m in (PRINT, FILE)}
"""medium name -> Medium, in `formats.MEDIA` order"""
CODEC_MEDIUM = {c: m.name for m in MEDIA.values() for c in m.codecs}
"""codec id -> the name of its medium, for every codec this build reads"""


def medium_of(codec: str) -> Medium:
    """The medium of a codec id (a snapshot's metadata or QR code names it); UserError for a codec this build
    does not read."""
    for m in MEDIA.values():
        if codec in m.codecs:
            return m
    known = ", ".join(f"{c} ({m.name})" for m in MEDIA.values() for c in m.codecs)
    raise UserError(f"unknown codec id {codec!r}: this build decodes {known}")
