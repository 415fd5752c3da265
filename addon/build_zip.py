"""Build the installable add-on: dist/lmrefine_blender.zip.

The zip holds the add-on folder lmrefine_blender/ with the lmrefine package
(Python files and the compiled lmrefine._native extension) under
lmrefine_blender/lib/, which the add-on puts on sys.path. The extension is
built for one Python (3.11 for Debian's Blender 3.4): build it first.

    /usr/bin/python3 addon/build_zip.py [--out dist/lmrefine_blender.zip]
"""

import argparse
import glob
import os
import sys
import zipfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
# Fixed timestamps: the same sources give the same zip.
EPOCH = (2020, 1, 1, 0, 0, 0)


def _tree(folder, prefix):
    """(path on disk, path in the zip) for every file under `folder`, caches left out."""
    pairs = []
    for directory, subdirectories, files in os.walk(folder):
        subdirectories[:] = sorted(d for d in subdirectories if d != "__pycache__")
        for name in sorted(files):
            if name.endswith((".pyc", ".pyo")):
                continue
            path = os.path.join(directory, name)
            pairs.append((path, os.path.join(prefix, os.path.relpath(path, folder))))
    return pairs


def files_to_pack():
    """(path on disk, path in the zip) pairs; raises SystemExit when the extension is missing."""
    addon = os.path.join(ROOT, "addon", "lmrefine_blender")
    package = os.path.join(ROOT, "python", "lmrefine")
    if not glob.glob(os.path.join(package, "_native*.so")):
        raise SystemExit(f"error: no compiled extension in {package}: run `make build` first")
    return _tree(addon, "lmrefine_blender") + _tree(package, os.path.join("lmrefine_blender", "lib", "lmrefine"))


def build(out):
    os.makedirs(os.path.dirname(out) or ".", exist_ok=True)
    temporary = out + ".part"
    with zipfile.ZipFile(temporary, "w", compression=zipfile.ZIP_DEFLATED) as archive:
        for source, name in files_to_pack():
            info = zipfile.ZipInfo(name, date_time=EPOCH)
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = (0o755 if name.endswith(".so") else 0o644) << 16
            with open(source, "rb") as stream:
                archive.writestr(info, stream.read())
    os.replace(temporary, out)  # never leave a half-written zip under the real name
    return out


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default=os.path.join(ROOT, "dist", "lmrefine_blender.zip"),
                        help="zip to write (default: dist/lmrefine_blender.zip)")
    args = parser.parse_args(argv)
    path = build(os.path.abspath(args.out))
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
