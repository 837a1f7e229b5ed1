"""Settings of `snapshot3d serve` (one `--option` each; torch-free, no FastAPI import)."""
from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

from snapshot3d.errors import UserError
from snapshot3d.options import config_field

__all__ = ["ServeConfig", "default_cache"]


def default_cache() -> str:
    """$XDG_CACHE_HOME/snapshot3d/scenes (~/.cache/snapshot3d/scenes)."""
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return str(Path(base) / "snapshot3d" / "scenes")


@dataclass(frozen=True)
class ServeConfig:
    host: str = config_field("127.0.0.1", "address to listen on (0.0.0.0: every interface, e.g. for a phone on "
                                          "the same network)")
    port: int = config_field(8000, "port to listen on")
    cache: str = config_field("", "folder the decoded scenes are kept in (empty: $XDG_CACHE_HOME/snapshot3d/scenes)")
    max_upload_mb: float = config_field(25.0, "largest upload accepted (MB); larger answers 413")
    max_pixels_mp: float = config_field(50.0, "largest photo accepted (megapixels, read from the file's header "
                                              "before decoding); larger answers 413")
    max_decodes: int = config_field(2, "decodes run at once; one more answers 503 with Retry-After (never queued)")
    timeout_s: float = config_field(30.0, "a decode that takes longer answers 503 (its result is dropped)")
    max_scenes: int = config_field(200, "scenes kept in the cache; the least recently used is evicted first")
    max_cache_mb: float = config_field(1024.0, "bytes kept in the cache (MB), all scenes together")
    max_render_size: int = config_field(1024, "largest `size` of an on-demand render (pixels)")
    render_probe_div: int = config_field(8, "views are rendered with a first-hit probe this many times smaller than "
                                            "the view (decode's default is 4; 8 costs 0.02 dB of restore_psnr in "
                                            "`bench decode`'s sweep and saves about a tenth of a view's time)")
    keep_baked: int = config_field(8, "baked grids kept in memory for /render (each about 30 MB); others are "
                                      "baked again from their scene file on use")
    read_timeout_s: float = config_field(15.0, "longest wait for the next piece of a request body (a body "
                                               "shorter than its Content-Length, or a stalled upload); 408")
    upload_timeout_s: float = config_field(120.0, "a whole request body must arrive within this; 408")
    header_timeout_s: float = config_field(10.0, "a request line and its headers must arrive within this after "
                                                 "the connection opens or the previous answer; 408")
    max_header_kb: float = config_field(64.0, "largest request line and headers (kB); larger answers 431")

    def checked(self) -> "ServeConfig":
        """Self, or a UserError naming the first option out of its range (every number finite)."""
        ranges = {"port": (0, 65535), "max_upload_mb": (0.001, 1e4), "max_pixels_mp": (0.01, 1e4),
                  "max_decodes": (1, 64), "timeout_s": (0.01, 86400), "max_scenes": (1, 1e6),
                  "max_cache_mb": (1, 1e7), "max_render_size": (16, 8192), "render_probe_div": (1, 64),
                  "keep_baked": (1, 1024), "read_timeout_s": (0.01, 3600), "upload_timeout_s": (0.01, 86400),
                  "header_timeout_s": (0.01, 3600), "max_header_kb": (1, 1024)}
        for name, (lo, hi) in ranges.items():
            v = getattr(self, name)
            if not (math.isfinite(v) and lo <= v <= hi):
                raise UserError(f"--{name.replace('_', '-')} {v!r} is out of range ({lo:g} to {hi:g})")
        return self

    def cache_dir(self) -> Path:
        return Path(self.cache or default_cache())
