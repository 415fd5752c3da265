"""docs/blender.md's settings table gives the add-on's real defaults (read
from addon/lmrefine_blender/properties.py without Blender)."""

import ast
import os
import re

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def property_defaults():
    tree = ast.parse(open(os.path.join(ROOT, "addon", "lmrefine_blender", "properties.py")).read())
    found = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and getattr(node.func, "id", "") in ("IntProperty", "FloatProperty"):
            keywords = {k.arg: k.value for k in node.keywords}
            if "name" in keywords and "default" in keywords:
                found[ast.literal_eval(keywords["name"])] = ast.literal_eval(keywords["default"])
    return found


def test_numeric_defaults_in_the_docs_are_the_code_defaults():
    table = {}
    for line in open(os.path.join(ROOT, "docs", "blender.md")):
        match = re.match(r"^\| ([A-Za-z ]+?) \| ([0-9.]+) \|", line)
        if match:
            table[match.group(1)] = float(match.group(2))
    defaults = property_defaults()
    checked = sorted(set(table) & set(defaults))
    assert {"Strength", "Max Magnification", "Min Shrink", "Resolution"} <= set(checked)
    for name in checked:
        assert table[name] == defaults[name], f"docs/blender.md says {name} = {table[name]}, the code {defaults[name]}"
