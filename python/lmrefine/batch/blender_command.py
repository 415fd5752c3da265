"""The headless Blender command of one level: the add-on's batch entry, as a single run uses it."""

import glob
import os
import shutil

PACKAGE_DIR = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def find_blender(explicit=None):
    """--blender, else $BLENDER, else `blender` on PATH."""
    blender = explicit or os.environ.get("BLENDER") or shutil.which("blender")
    if not blender or not (os.path.isfile(blender) or shutil.which(blender)):
        raise OSError(f"Blender not found ({blender or 'not on PATH'}): install it (apt-get install blender), "
                      "or give --blender PATH or set $BLENDER")
    return blender


def addon_script_candidates(script):
    """Where the add-on's headless entry `script` (batch.py, export_scene.py)
    may be, most specific first."""
    candidates = []
    # A checkout: python/lmrefine/ beside addon/lmrefine_blender/.
    candidates.append(os.path.join(PACKAGE_DIR, "..", "..", "addon", "lmrefine_blender", script))
    # The add-on zip puts lmrefine under lmrefine_blender/lib/.
    candidates.append(os.path.join(PACKAGE_DIR, "..", "..", script))
    # An add-on installed into Blender's user scripts.
    if os.environ.get("BLENDER_USER_SCRIPTS"):
        candidates.append(os.path.join(os.environ["BLENDER_USER_SCRIPTS"], "addons", "lmrefine_blender", script))
    candidates.extend(sorted(glob.glob(os.path.expanduser(
        f"~/.config/blender/*/scripts/addons/lmrefine_blender/{script}")), reverse=True))
    return [os.path.normpath(c) for c in candidates]


def batch_script_candidates():
    """Where the add-on's batch.py may be, most specific first."""
    extra = [os.path.normpath(os.environ["LMREFINE_BATCH_SCRIPT"])] if os.environ.get("LMREFINE_BATCH_SCRIPT") else []
    return extra + addon_script_candidates("batch.py")


def find_batch_script(explicit=None):
    if explicit:
        if not os.path.isfile(explicit):
            raise OSError(f"--batch-script '{explicit}' does not exist")
        return os.path.abspath(explicit)
    candidates = batch_script_candidates()
    for candidate in candidates:
        if os.path.isfile(candidate):
            return candidate
    raise OSError("the add-on's batch entry (lmrefine_blender/batch.py) was not found; looked in: "
                  + ", ".join(candidates) + ". Install the add-on (docs/blender.md), run from a checkout, "
                  "or set $LMREFINE_BATCH_SCRIPT")


def blender_command(blender, script, level_path, out_dir, flags, threads):
    """`blender -b LEVEL --factory-startup --python-exit-code 1 -t N --python batch.py -- FLAGS --out DIR`."""
    command = [blender, "-b", level_path, "--factory-startup", "--python-exit-code", "1"]
    if threads:
        command += ["-t", str(threads)]
    return command + ["--python", script, "--", *flags, "--out", out_dir]


def blender_environment(threads):
    """The environment of one Blender: the native pool sized to its share."""
    env = dict(os.environ)
    if threads:
        env["LMREFINE_THREADS"] = str(threads)
    return env
