"""Training (torch): `train.field` fits scenes and trains the shared decoder; `train.codec` holds the
codecs that hide a scene in a photo, their training and their embedding. Nothing is imported here:
each room is imported when a command needs it, so that `snapshot3d --help` stays fast."""

__all__ = ["field", "codec"]
