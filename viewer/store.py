"""Decoded scenes kept by `snapshot3d serve`: one folder per scene under a cache folder, named by a random
token, published atomically (written into a hidden sibling, then renamed), bounded in count and bytes
with least-recently-used eviction (a scene's folder mtime is its last use).

Files of a scene: scene.s3d, report.json, grid.bin.gz (`viewer.gridfile`, gzip), capture.png (the
rectified capture the restore read), and on first request views/NNN.png and mesh.glb (each written atomically)."""
from __future__ import annotations

import os
import re
import secrets
import shutil
import tempfile
import threading
from dataclasses import dataclass
from pathlib import Path

__all__ = ["StoreLimits", "SceneStore"]

_ID = re.compile(r"^[A-Za-z0-9_-]{16}$")


@dataclass(frozen=True)
class StoreLimits:
    max_scenes: int = 200
    """scenes kept; the least recently used goes first"""
    max_mb: float = 1024.0
    """bytes kept (MB), all scenes together"""


def _size(folder: Path) -> int:
    return sum(p.stat().st_size for p in folder.rglob("*") if p.is_file())


class SceneStore:
    def __init__(self, root, limits: StoreLimits = StoreLimits()):
        self.root = Path(root)
        self.root.mkdir(parents=True, exist_ok=True)
        self.limits = limits
        self._lock = threading.Lock()
        for stale in self.root.glob(".*"):  # staging and upload folders left by a server that was killed
            shutil.rmtree(stale, ignore_errors=True)

    def staging(self) -> Path:
        """A fresh hidden folder to write a scene into (then `publish` or `discard` it)."""
        return Path(tempfile.mkdtemp(prefix=".scene.", suffix=".partial", dir=self.root))

    def discard(self, tmp: Path) -> None:
        shutil.rmtree(tmp, ignore_errors=True)

    def publish(self, tmp: Path) -> str:
        """Move a staged folder into place under a new random id; evict to the limits; return the id."""
        with self._lock:
            sid = secrets.token_urlsafe(12)
            tmp.rename(self.root / sid)
            self._evict(keep=sid)
        return sid

    def folder(self, sid: str) -> Path | None:
        """The scene's folder (its use recorded), or None for an unknown or malformed id."""
        if not _ID.match(sid):
            return None
        path = self.root / sid
        try:
            os.utime(path)
        except FileNotFoundError:
            return None
        return path

    def ids(self) -> list[str]:
        """Published scenes, least recently used first."""
        scenes = [p for p in self.root.iterdir() if p.is_dir() and _ID.match(p.name)]
        return [p.name for p in sorted(scenes, key=lambda p: p.stat().st_mtime_ns)]

    def _evict(self, keep: str) -> None:
        ids = [s for s in self.ids() if s != keep]
        sizes = {s: _size(self.root / s) for s in ids}
        total = sum(sizes.values()) + _size(self.root / keep)
        while ids and (len(ids) + 1 > self.limits.max_scenes or total > self.limits.max_mb * 1e6):
            old = ids.pop(0)
            total -= sizes[old]
            shutil.rmtree(self.root / old, ignore_errors=True)
