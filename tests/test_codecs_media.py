"""The media registry (`snapshot3d.codecs.media`): each codec id belongs to one medium, an unknown one is
refused in one line naming the known ones, and plane limits are checked with a message naming the medium
and its range (the same limits the codecs' own checks use)."""
import pytest

from snapshot3d import formats
from snapshot3d.codecs import file_layout, print_source
from snapshot3d.codecs.media import CODEC_MEDIUM, FILE, MEDIA, PRINT, medium_of
from snapshot3d.errors import UserError


def test_every_codec_has_one_medium():
    assert tuple(MEDIA) == formats.MEDIA
    assert CODEC_MEDIUM == {**{c: "print" for c in formats.PRINT_CODECS}, **{c: "file" for c in formats.FILE_CODECS}}
    assert {m.name: m.codec for m in MEDIA.values()} == {"print": formats.PRINT_CODEC, "file": formats.FILE_CODEC}
    assert medium_of("print-1") is PRINT and medium_of(formats.FILE_CODEC) is FILE
    assert (PRINT.file_scale, FILE.file_scale) == (1, formats.FILE_SCALE)


def test_unknown_codec_is_refused_in_one_line():
    with pytest.raises(UserError) as e:
        medium_of("print-9")
    msg = str(e.value)
    assert "\n" not in msg and msg.startswith("unknown codec id 'print-9': this build decodes print-2 (print)")
    assert all(f"{c} ({m})" in msg for c, m in CODEC_MEDIUM.items())


@pytest.mark.parametrize("medium, channels, res, ok", [
    (PRINT, 12, 4, True), (PRINT, 13, 32, False), (PRINT, 4, 3, False), (PRINT, 4, 65, False), (PRINT, 0, 16, False),
    (FILE, 8, 2, True), (FILE, 9, 32, False), (FILE, 4, 1, False), (FILE, 4, 64, True), (FILE, 4, 65, False)])
def test_plane_limits(medium, channels, res, ok):
    own = {"print": print_source.check_print_planes, "file": file_layout.check_plane_shape}[medium.name]
    if ok:
        medium.check_planes(channels, res)
        own(channels, res)
        return
    with pytest.raises(UserError, match=rf"{channels} channels of {res}x{res}.* \(medium {medium.name}\)$"):
        medium.check_planes(channels, res)
    with pytest.raises(ValueError) as e:
        own(channels, res)
    assert str(e.value) == medium.plane_error(channels, res)
    limits = "at most 8 channels and 64x64" if medium is FILE else "4x4 to 64x64 with 1 to 12 channels"
    assert limits in str(e.value)
