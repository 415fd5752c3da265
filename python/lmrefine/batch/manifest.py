"""OUT/manifest.json: what each level of a batch is and how far it got.

One record per level: input (path, sha256, size, mtime), the options it was
run with, status (pending, running, done, failed, interrupted), outputs,
attempts, seconds, objects, error and log path. Written atomically (a
temporary file renamed over the old one) after every change, so a crash or
Ctrl-C at any moment leaves the last complete state.
"""

import hashlib
import json
import os
import time

VERSION = 1
FILENAME = "manifest.json"


def options_key(options):
    """A stable hash of the flags a level runs with."""
    return hashlib.sha256(json.dumps(options, sort_keys=True).encode()).hexdigest()[:16]


def write_json_atomic(path, data):
    temporary = f"{path}.tmp-{os.getpid()}"
    with open(temporary, "w", encoding="utf-8") as stream:
        json.dump(data, stream, indent=2, sort_keys=True)
        stream.flush()
        os.fsync(stream.fileno())
    os.replace(temporary, path)


class Manifest:
    def __init__(self, out_dir):
        self.path = os.path.join(out_dir, FILENAME)
        self.levels = {}
        if os.path.exists(self.path):
            try:
                with open(self.path, encoding="utf-8") as stream:
                    data = json.load(stream)
            except (OSError, ValueError) as error:
                raise OSError(f"cannot read the batch manifest '{self.path}': {error}; move it away to start "
                              "the batch afresh") from None
            self.levels = data.get("levels", {})

    def record(self, name):
        return self.levels.get(name)

    def update(self, name, **fields):
        record = self.levels.setdefault(name, {})
        record.update(fields)
        record["updated"] = time.strftime("%Y-%m-%dT%H:%M:%S%z")
        return record

    def save(self):
        write_json_atomic(self.path, {"version": VERSION, "levels": self.levels})

    def decide(self, name, fingerprint, options, out_dir, force=False):
        """(run?, reason): skip a level only when its last run finished,
        its input and options are the same and its outputs are still there."""
        record = self.levels.get(name)
        if force:
            return True, "--force"
        if record is None:
            return True, "new"
        if record.get("status") != "done":
            return True, f"was {record.get('status', 'unknown')}"
        if record.get("input", {}).get("hash") != fingerprint["hash"]:
            return True, "input changed"
        if record.get("options_key") != options_key(options):
            return True, "options changed"
        if not os.path.isfile(os.path.join(out_dir, name, "report.json")):
            return True, "outputs missing"
        return False, "unchanged"
