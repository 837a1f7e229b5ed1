"""Settings of `snapshot3d serve` (one `--option` each; torch-free, no FastAPI import)."""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

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

    def cache_dir(self) -> Path:
        return Path(self.cache or default_cache())
