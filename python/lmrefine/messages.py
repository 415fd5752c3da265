"""Error messages as a user reads them (the add-on's popups, the batch's
command line): the native core appends the C++ source location of the check
that fired ("... [baker.cpp:231]"), which helps a bug report but means
nothing to an artist; the full text stays in the logs."""

import re

_LOCATION = re.compile(r"\s*\[[A-Za-z0-9_./\\-]+\.(?:cpp|h|hpp|cc):\d+\]")


def without_source_location(text):
    """`text` without native source locations ("[file.cpp:123]")."""
    return _LOCATION.sub("", str(text))


def user_message(error):
    """One line for a user: lmrefine's own errors (ValueError, TypeError,
    OSError, MemoryError name the problem and the fix) as they are, anything
    else with its type; no native source locations."""
    text = without_source_location(error)
    if isinstance(error, (ValueError, TypeError, OSError, MemoryError)):
        return text
    return f"{type(error).__name__}: {text}" if text else type(error).__name__
