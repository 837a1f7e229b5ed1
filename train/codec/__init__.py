"""The codecs that hide a scene's planes in a host photo (torch): the `file` medium's invertible network
(`net`, `hinet`: weights, embed, restore), its training data (`data`), differentiable channel (`channel`),
training (`training`) and embed-time refinement (`refine`); the capture channel's capacity model
(`capacity`) and an oracle scanner (`oracle`); the `embed`, `restore`, `train codec` and `make-example`
commands (`commands`, `example`). Submodules are imported where they are used (nothing at import time)."""

__all__ = ["net", "hinet", "data", "channel", "training", "refine", "capacity", "oracle", "config", "commands",
           "example"]
