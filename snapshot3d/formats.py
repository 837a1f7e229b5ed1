"""Constants of the snapshot3d formats, in one place (STYLE: one module for format constants).

Everything a scene file, the renderers and (later) the sheet and codec must agree on lives here.
"""
from __future__ import annotations

__all__ = [
    "SCENE_FORMAT_VERSION", "DECODERS", "DECODER_VERSION", "decoder_number", "C_MAX", "PLANE_AXES", "PLANE_NAMES", "PLANE_RANGE",
    "ORBIT_VIEWS", "ORBIT_SIZE", "ORBIT_ELEVATION_DEG", "ORBIT_FOV_DEG", "WORLD_UP", "BACKGROUND",
    "DENSITY_CLAMP", "RENDER_STEPS_PER_BOX", "OCC_RES", "OCC_ALPHA_THRESHOLD", "KB",
    # sheet and scan (issue 3)
    "SNAPSHOT_SIZE", "SHEET_FORMAT_VERSION", "FILE_CODEC", "FILE_CODECS", "PRINT_CODEC", "PRINT_CODECS", "MEDIA",
    "MARK_CODECS", "DEFAULT_MEDIUM", "FILE_REFINE_STEPS", "FILE_SCALE", "CODEC_CHANNELS", "CODEC_MAX_RES", "CODEC_LEVELS", "CODEC_GRID", "ARUCO_DICT", "SHEET_MARKER_IDS", "MARKER_SIZE",
    "MARKER_GAP", "MARGIN_X", "MARGIN_Y", "COLUMN_LEFT", "COLUMN_RIGHT", "SHEET_BOX", "MARKER_ORIGINS",
    "PATCH_COLOURS", "PATCH_ROWS", "PATCH_COLS", "PATCH_BOX", "QR_BOX", "HEAD_CODE_SIZE", "HEAD_CODE_BOXES",
    "QR_MAGIC", "QR_SEP", "QR_FIELDS",
    "SEVERITIES",
]

SCENE_FORMAT_VERSION = 1
# The shared decoder MLP (features -> density, colour). A scene names the version it was fitted for and
# is decoded with that one; a version not in DECODERS is refused. New scenes are fitted for
# DECODER_VERSION unless `fit --decoder` names another. Add a version (never change one) when the decoder's
# weights or definition change. tri-dec-2 (wider, trained for small planes too) fits every scene better but
# loses 0.3-0.8 dB through a print (bench/results/decoders.json), so tri-dec-1 stays the default.
DECODERS = ("tri-dec-1", "tri-dec-2")
DECODER_VERSION = "tri-dec-1"


def decoder_number(version: str) -> int | None:
    """'tri-dec-N' -> N (what a sheet's QR code carries), None for a text of another form."""
    head, _, n = version.rpartition("-")
    return int(n) if head == "tri-dec" and n.isascii() and n.isdigit() and len(n) <= 4 else None


# Planes carry C <= C_MAX channels; the decoder reads 3*C_MAX features, unused channels are zero.
C_MAX = 12
# Axis pairs of the three planes (XY, XZ, YZ), in box-normalised coordinates.
PLANE_AXES = ((0, 1), (0, 2), (1, 2))
PLANE_NAMES = ("xy", "xz", "yz")
# Plane values are kept in [-1, 1] and carried as 8-bit codes: v = code / 255 * 2 - 1.
PLANE_RANGE = (-1.0, 1.0)

# The decode orbit (the paper's mobile setting): 20 views of 380x380 around the scene.
ORBIT_VIEWS = 20
ORBIT_SIZE = 380
ORBIT_ELEVATION_DEG = 20.0
ORBIT_FOV_DEG = 40.0
WORLD_UP = (0.0, 0.0, 1.0)
BACKGROUND = 1.0  # white

# Rendering: exp() of the density head is clamped here; sample spacing is box_diagonal / steps.
DENSITY_CLAMP = 15.0
RENDER_STEPS_PER_BOX = 192  # samples along the longest ray through the (normalised) box
OCC_RES = 64                # occupancy grid cells per axis
OCC_ALPHA_THRESHOLD = 0.01  # a cell is occupied when one step through it has alpha above this
KB = 1000                   # scene_kb is in kilobytes of 1000 bytes

# --- sheet and scan (issue 3) ---
# The printed sheet (DESIGN 1.3): the snapshot in the middle, a column either side holding a corner
# ArUco marker at the top and the bottom, the colour patches (left) and the QR code (right), with a
# thin quiet zone around everything. Geometry is in "layout units" = pixels of the snapshot, with
# the snapshot's top-left pixel corner at (0, 0) and x to the right, y down; a sheet image is the
# layout scaled by an integer factor (each snapshot pixel printed as k x k dots).
SNAPSHOT_SIZE = 380           # the codec's snapshot is SNAPSHOT_SIZE x SNAPSHOT_SIZE RGB (not ORBIT_SIZE)
SHEET_FORMAT_VERSION = 1
ARUCO_DICT = "DICT_4X4_50"    # cv2.aruco predefined dictionary of the sheet's markers
# Marker ids by sheet format version; the four ids identify the format. Order: top-left, top-right,
# bottom-right, bottom-left corner of the sheet (as seen upright).
SHEET_MARKER_IDS = {1: (0, 1, 2, 3)}
MARKER_SIZE = 78              # marker side (4x4 bits + 1-bit border = 6 cells of 13)
MARKER_GAP = 8                # white gap between the snapshot and a column
MARGIN_X = 12                 # quiet zone outside the columns (left and right)
MARGIN_Y = 19                 # quiet zone above and below the snapshot
COLUMN_LEFT = -(MARKER_GAP + MARKER_SIZE)   # x of the left column's left edge
COLUMN_RIGHT = SNAPSHOT_SIZE + MARKER_GAP   # x of the right column's left edge
# Layout box of the whole sheet: (x0, y0, x1, y1).
SHEET_BOX = (COLUMN_LEFT - MARGIN_X, -MARGIN_Y, COLUMN_RIGHT + MARKER_SIZE + MARGIN_X, SNAPSHOT_SIZE + MARGIN_Y)
# Top-left corner (x, y) of each marker, in SHEET_MARKER_IDS order.
MARKER_ORIGINS = ((COLUMN_LEFT, 0), (COLUMN_RIGHT, 0), (COLUMN_RIGHT, SNAPSHOT_SIZE - MARKER_SIZE),
                  (COLUMN_LEFT, SNAPSHOT_SIZE - MARKER_SIZE))
# Colour patches: a grid of PATCH_ROWS x PATCH_COLS cells in the left column, row-major, sRGB in [0, 1].
PATCH_COLOURS = (
    (1.0, 1.0, 1.0), (0.0, 0.0, 0.0),
    (0.8, 0.8, 0.8), (0.2, 0.2, 0.2),
    (0.6, 0.6, 0.6), (0.4, 0.4, 0.4),
    (1.0, 0.0, 0.0), (0.0, 1.0, 1.0),
    (0.0, 1.0, 0.0), (1.0, 0.0, 1.0),
    (0.0, 0.0, 1.0), (1.0, 1.0, 0.0),
)
PATCH_ROWS, PATCH_COLS = 6, 2
PATCH_BOX = (COLUMN_LEFT, MARKER_SIZE + MARKER_GAP + 4, COLUMN_LEFT + MARKER_SIZE,
             SNAPSHOT_SIZE - MARKER_SIZE - MARKER_GAP - 4)   # (x0, y0, x1, y1) of the patch grid
QR_BOX = (COLUMN_RIGHT, (SNAPSHOT_SIZE - MARKER_SIZE) // 2, COLUMN_RIGHT + MARKER_SIZE,
          (SNAPSHOT_SIZE + MARKER_SIZE) // 2)                # the QR code's square, quiet zone outside it
# A scene's own head (`snapshot3d.head`) on a sheet: two smaller QR codes in the right column, above and below the
# QR code, each HEAD_CODE_SIZE square and at least 6 units from the markers and the QR code (`scanner.headcode`).
HEAD_CODE_SIZE = 60
HEAD_CODE_BOXES = tuple((COLUMN_RIGHT + (MARKER_SIZE - HEAD_CODE_SIZE) // 2, y0,
                         COLUMN_RIGHT + (MARKER_SIZE - HEAD_CODE_SIZE) // 2 + HEAD_CODE_SIZE, y0 + HEAD_CODE_SIZE)
                        for y0 in (MARKER_SIZE + 6, SNAPSHOT_SIZE - MARKER_SIZE - 6 - HEAD_CODE_SIZE))
# QR payload: fields joined by QR_SEP; the first two are always present, the rest optional:
#   "S3D<version>", codec id, "b=" scene box x0,y0,z0,x1,y1,z1, "o=" orbit radius,elevation_deg,fov_deg.
QR_MAGIC = "S3D"
QR_SEP = "|"
QR_FIELDS = ("version", "codec", "box", "orbit")
# The print-and-capture channel's severities, mildest first (`scanner.presets.PRESETS` holds one preset per
# name): `none`, `jpeg90` and `jpeg75` are digital copies of the sheet image, the rest a print and a phone photo.
SEVERITIES = ("none", "jpeg90", "jpeg75", "mild", "moderate", "severe")

# --- media and their codecs (DESIGN 1.2) ---
# A snapshot travels through one of two media, each with its own codec; the snapshot file's metadata and
# the sheet's QR code name the codec, and decoding picks it from there (an unknown one is refused).
PRINT_CODEC = "print-2"       # id of the print medium's codec that `embed` writes (`snapshot3d.codecs.print_embed`)
PRINT_CODECS = (PRINT_CODEC, "print-1")   # the print codecs this build reads (print-1: no folded carriers)
MEDIA = ("print", "file")
FILE_CODEC = "hinet-3"        # id of the file medium's codec that `embed` writes (weights, ONNX and QR name it)
FILE_CODECS = (FILE_CODEC, "hinet-2", "hinet-1")  # the file codecs this build reads (older snapshots name older ones)
# (which codec belongs to which medium, and what each carries: `snapshot3d.codecs.media`)
MARK_CODECS = ("hinet-1", "hinet-2", "print-1", "hinet-3", "print-2")   # a pixel mark's codec byte indexes this (append only, never reorder)
DEFAULT_MEDIUM = "print"      # a snapshot is made to be printed unless it is asked for as a file
CALIB_CODEC = "calib-2"       # the QR codec id of the calibration chart (`sheet --calibration`): decode refuses it,
                              # `snapshot3d calibrate` measures it (`scanner.chart`); calib-1 is no longer read

# --- the file medium's codec (issue 4) ---
# The secret is the scene's planes, each channel spread over the whole wavelet grid of the snapshot
# (CODEC_GRID x CODEC_GRID: SNAPSHOT_SIZE after CODEC_LEVELS Haar splits) by separable linear
# interpolation, so that restoring a texel averages over about (CODEC_GRID / R)^2 grid cells. A codec carries planes up to
# CODEC_MAX_RES x CODEC_MAX_RES with at most CODEC_CHANNELS channels; fewer channels are zero-padded.
FILE_REFINE_STEPS = 50        # embed-time refinement steps of a file snapshot (`embed --refine`'s default)
FILE_SCALE = 4                # a file snapshot is written at FILE_SCALE x SNAPSHOT_SIZE, each pixel a square of
                              # FILE_SCALE^2 (a shared copy's JPEG then quantises 2x2 snapshot pixels per 8x8 block)
CODEC_CHANNELS = 8            # plane channels the secret has room for (3 planes -> 24 secret channels)
CODEC_MAX_RES = 64            # largest plane resolution the codec carries
CODEC_LEVELS = 2              # Haar splits of the shipped codec (its weights file stores its own config)
CODEC_GRID = SNAPSHOT_SIZE >> CODEC_LEVELS   # 95: the secret's grid
