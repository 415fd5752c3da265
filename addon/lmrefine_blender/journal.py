"""Rollback journal: a failed or cancelled run leaves the scene as it was.

Every change the pipeline makes registers the action that reverts it; on
failure the actions run newest first. A change that keeps something aside
for its revert (the untouched mesh of a tessellation) also registers the
action that drops it once the run succeeded. Undo (Ctrl+Z) cannot serve here: a
cancelled modal operator pushes no undo step, and a batch run has no undo.
"""


class Journal:
    def __init__(self):
        self._actions = []
        self._on_commit = []

    def on_rollback(self, action):
        self._actions.append(action)

    def on_commit(self, action):
        """`action` runs when the run succeeded (commit), never after a rollback."""
        self._on_commit.append(action)

    def rollback(self):
        """Run every revert action, newest first; the first error is re-raised after all ran."""
        first_error = None
        while self._actions:
            action = self._actions.pop()
            try:
                action()
            except Exception as error:  # keep reverting the rest
                first_error = first_error or error
        self._on_commit.clear()
        if first_error is not None:
            raise first_error

    def commit(self):
        self._actions.clear()
        actions, self._on_commit = self._on_commit, []
        for action in actions:
            action()
