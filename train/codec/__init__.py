"""The codecs that hide a scene's planes in a host photo (torch): the `file` medium's invertible network
(`net`, `hinet`: weights, embed, restore), its training data (`data`), differentiable channel (`channel`),
training (`training`) and embed-time refinement (`refine`); each medium's embedder (`embedding`); the
`embed`, `train codec` and `make-example` commands (`commands`, `example`). Submodules are imported where
they are used (nothing at import time)."""

__all__ = ["net", "hinet", "data", "channel", "training", "refine", "embedding", "config", "commands",
           "example"]
