"""What the Blender add-on's bridge costs on a large mesh, against Blender's raw array copies.

Baseline: the bare `foreach_get` copies of the arrays the bridge needs
(vertex positions, corner vertex indices, corner normals, loop triangles, one
UV map), i.e. what any exporter pays to get the data out of Blender. The
bridge's steps are printed as ratios to it.

    PYTHONPATH=python /usr/bin/python3 bench/bench_blender_bridge.py [--subdivisions N]

Run with Python, it starts headless Blender on itself.
"""

import os
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)


def in_blender(subdivisions):
    import bpy
    import numpy as np

    sys.path[:0] = [os.path.join(REPO, "python"), os.path.join(REPO, "addon"), HERE]
    from lmrefine_blender import bridge
    from timing import best_of

    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=subdivisions, y_subdivisions=subdivisions, size=4.0)
    obj = bpy.context.active_object
    mesh = obj.data
    mesh.uv_layers.new(name="Lightmap")
    mesh.calc_loop_triangles()
    mesh.calc_normals_split()
    bpy.context.evaluated_depsgraph_get()  # evaluate once, outside the timings

    def least(function):
        return best_of(3, function)[0]

    def raw_copies():
        for collection, attribute, width, dtype in (
                (mesh.vertices, "co", 3, np.float32), (mesh.loops, "vertex_index", 1, np.int32),
                (mesh.loops, "normal", 3, np.float32), (mesh.loop_triangles, "loops", 3, np.int32),
                (mesh.uv_layers["Lightmap"].data, "uv", 2, np.float32)):
            values = np.empty(len(collection) * width, dtype=dtype)
            collection.foreach_get(attribute, values)

    baseline = least(raw_copies)
    rows = [
        ("foreach_get copies (baseline)", baseline),
        ("read_layout (+ weld)", least(lambda: bridge.read_layout(mesh, "Lightmap"))),
        ("export_scene (evaluated, world space)",
         least(lambda: bridge.export_scene(bpy.context, [obj], {obj.name: "Lightmap"}))),
    ]
    print(f"{len(mesh.loop_triangles)} triangles, {len(mesh.loops)} face corners")
    print(f"{'step':40s} {'seconds':>8s} {'ratio':>6s}")
    for name, seconds in rows:
        print(f"{name:40s} {seconds:8.3f} {seconds / baseline:6.2f}")


def main(argv):
    subdivisions = int(argv[argv.index("--subdivisions") + 1]) if "--subdivisions" in argv else 500
    process = subprocess.run(["blender", "-b", "--factory-startup", "--python-exit-code", "1", "--python",
                              os.path.abspath(__file__), "--", "--in-blender", str(subdivisions)],
                             capture_output=True, text=True)
    lines = process.stdout.splitlines()
    start = next((i for i, line in enumerate(lines) if "face corners" in line), None)
    if process.returncode != 0 or start is None:
        sys.stderr.write(process.stdout[-2000:] + process.stderr[-2000:])
        return 1
    print("\n".join(lines[start:start + 5]))
    return 0


if __name__ == "__main__":
    if "--in-blender" in sys.argv:
        in_blender(int(sys.argv[sys.argv.index("--in-blender") + 1]))
    else:
        sys.exit(main(sys.argv[1:]))
