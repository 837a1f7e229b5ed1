"""The bench's scenes (`bench fit`, `bench fit --representations`), torch-free so that a command can refuse an
unknown scene before it loads anything heavy."""
from __future__ import annotations

from snapshot3d.errors import UserError
from snapshot3d.train.field.config import FitConfig

__all__ = ["BENCH_SCENES", "checked_scenes", "load_bench_scene"]

# name: (scene spec relative to ../shared/data or builtin, loader kwargs, fit config of the size sweep,
#        step counts of the time sweep besides the size sweep's R64 C8 point)
BENCH_SCENES = {
    "spot": ("builtin:spot", {"size": 200}, FitConfig(), (300, 750)),
    "lego": ("scenes/lego_subset", {"downscale": 4}, FitConfig(), (300, 750, 3000)),  # 20 views: 3000 steps pays
}


def checked_scenes(text: str) -> list[str]:
    """--scenes "spot,lego" -> ["spot", "lego"]; UserError naming the first unknown one, before anything runs."""
    scenes = [s for s in text.split(",") if s]
    unknown = [s for s in scenes if s not in BENCH_SCENES]
    if unknown:
        raise UserError(f"--scenes: unknown bench scene {unknown[0]!r} (choose from {', '.join(BENCH_SCENES)})")
    return scenes


def load_bench_scene(name: str):
    """(PosedImages, FitConfig) of bench scene `name`; UserError when its shared data is absent."""
    from snapshot3d.builtin import shared_data_dir
    from snapshot3d.loaders import load_scene
    spec, kw, cfg, _ = BENCH_SCENES[name]
    if not spec.startswith("builtin:"):
        root = shared_data_dir()
        if root is None:
            raise UserError(f"bench fit needs ../shared/data for {name} (not found)")
        spec = str(root / spec)
    return load_scene(spec, **kw), cfg
