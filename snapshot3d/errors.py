"""The one exception type for a user's mistake: the CLI prints its message on one line and exits 1."""

__all__ = ["UserError"]


class UserError(Exception):
    """Bad input or a request that cannot be met; `str(err)` is a one-line cause for the user."""
