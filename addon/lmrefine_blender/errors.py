"""The two ways a run ends early that are not bugs, and how messages name a setting."""

# Who reads the messages: the panel's user (False), or the batch's (batch.main sets True). A message names
# a setting as its reader changes it: by its label in the panel, or by its command-line flag.
BATCH = False


def setting(panel, batch):
    """`panel` (a setting as the panel names it, or what to do there) for the add-on's user, `batch` (the
    same with the batch's flag) for the batch's."""
    return batch if BATCH else panel


class UserError(Exception):
    """A problem the user can fix; the message says how."""


class Cancelled(Exception):
    """The user pressed Esc (or a progress callback asked to stop)."""
