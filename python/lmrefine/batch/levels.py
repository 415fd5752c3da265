"""The levels of a batch: .blend files named on the command line or found in folders."""

import hashlib
import os


class Level:
    """One input .blend and the name its outputs go under (OUT/<name>/)."""

    def __init__(self, path, name):
        self.path = os.path.abspath(path)
        self.name = name

    def __repr__(self):
        return f"Level({self.name!r}, {self.path!r})"


def find_levels(inputs):
    """Levels from files and folders (a folder gives its *.blend files, not
    recursively; Blender's .blend1 backups are left out). Names are the file
    stems; two files of one stem get their folder's name in front. Raises
    ValueError naming what is wrong."""
    paths = []
    for item in inputs:
        if os.path.isdir(item):
            found = sorted(os.path.join(item, f) for f in os.listdir(item) if f.endswith(".blend"))
            if not found:
                raise ValueError(f"folder '{item}' has no .blend files: give .blend files or a folder of them")
            paths.extend(found)
        elif os.path.isfile(item):
            if not item.endswith(".blend"):
                raise ValueError(f"'{item}' is not a .blend file: give .blend files or folders of them")
            paths.append(item)
        else:
            raise ValueError(f"level '{item}' does not exist: check the path")
    unique = list(dict.fromkeys(os.path.abspath(p) for p in paths))
    stems = [os.path.splitext(os.path.basename(p))[0] for p in unique]
    names = []
    for path, stem in zip(unique, stems):
        name = stem if stems.count(stem) == 1 else f"{os.path.basename(os.path.dirname(path))}_{stem}"
        names.append(name)
    clashes = sorted({n for n in names if names.count(n) > 1})
    if clashes:
        raise ValueError(f"several levels would be written to OUT/{clashes[0]}: rename the files so their names differ")
    return [Level(path, name) for path, name in zip(unique, names)]


def file_hash(path):
    """sha256 of a file's bytes, read in 1 MiB blocks."""
    digest = hashlib.sha256()
    with open(path, "rb") as stream:
        for block in iter(lambda: stream.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def input_fingerprint(path, known=None):
    """{"hash", "size", "mtime_ns"} of a level file. When `known` (the
    manifest's last record) has the same size and modification time, its
    hash is reused rather than reading the file again (as git and make do):
    resuming a large batch then reads no level."""
    stat = os.stat(path)
    if known and known.get("size") == stat.st_size and known.get("mtime_ns") == stat.st_mtime_ns and known.get("hash"):
        return {"hash": known["hash"], "size": stat.st_size, "mtime_ns": stat.st_mtime_ns}
    return {"hash": file_hash(path), "size": stat.st_size, "mtime_ns": stat.st_mtime_ns}
