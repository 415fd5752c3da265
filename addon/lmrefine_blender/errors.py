"""The two ways a run ends early that are not bugs."""


class UserError(Exception):
    """A problem the user can fix; the message says how."""


class Cancelled(Exception):
    """The user pressed Esc (or a progress callback asked to stop)."""
