#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <memory>
#include <limits>
#include <string>

#include "lmrefine/core/error.h"
#include "lmrefine/bake/scene.h"
#include "numpy_util.h"

namespace py = pybind11;

namespace lmrefine::bindings {
namespace {

glm::vec3 vec3_param(const py::handle& value, const char* name) {
    auto array = py_util::contiguous<float>(value, name);
    if (array.size() != 3) throw py::value_error(std::string(name) + " must be 3 numbers (x, y, z) or (r, g, b)");
    return {array.data()[0], array.data()[1], array.data()[2]};
}

// Blender's matrix_world as rows (np.array(obj.matrix_world) or nested
// lists); glm is column-major.
glm::mat4 matrix_param(const py::handle& value) {
    auto array = py_util::contiguous<float>(value, "matrix");
    if (array.ndim() != 2 || array.shape(0) != 4 || array.shape(1) != 4) {
        throw py::value_error("matrix must be a 4x4 world matrix (Blender's obj.matrix_world, row by row)");
    }
    glm::mat4 m;
    for (int r = 0; r < 4; ++r) {
        for (int c = 0; c < 4; ++c) m[c][r] = array.at(r, c);
    }
    return m;
}

AreaShape parse_shape(const std::string& shape) {
    if (shape == "SQUARE") return AreaShape::Square;
    if (shape == "RECTANGLE") return AreaShape::Rectangle;
    if (shape == "DISK") return AreaShape::Disk;
    if (shape == "ELLIPSE") return AreaShape::Ellipse;
    throw py::value_error("shape must be \"SQUARE\", \"RECTANGLE\", \"DISK\" or \"ELLIPSE\", got \"" + shape + "\"");
}

int add_mesh(Scene& scene, const py::handle& positions_in, const py::handle& triangles_in, const py::handle& uvs_in,
             const py::handle& normals_in, const py::handle& base_color_in, const py::handle& receiver_in) {
    const bool receiver = py_util::bool_param(receiver_in, "receiver");
    auto positions = py_util::require_points(positions_in, "positions", 3);
    auto triangles = py_util::require_indices(triangles_in, "triangles", 3);
    MeshInput in;
    in.positions = positions.data();
    in.vertex_count = positions.shape(0);
    in.triangles = triangles.data();
    in.triangle_count = triangles.shape(0);
    in.receiver = receiver;
    py_util::FloatArray uvs, normals;
    if (!uvs_in.is_none()) {
        uvs = py_util::require_points(uvs_in, "uvs", 2);
        if (uvs.shape(0) != in.triangle_count * 3) {
            throw py::value_error("uvs must be per corner, shape (T*3, 2) = (" + std::to_string(in.triangle_count * 3) +
                                  ", 2) with corner k of triangle t at row 3t+k (as Blender's loop triangles), got " +
                                  py_util::shape_string(uvs));
        }
        in.uvs = uvs.data();
    }
    if (!normals_in.is_none()) {
        normals = py_util::require_points(normals_in, "normals", 3);
        in.normals = normals.data();
        in.normal_count = normals.shape(0);
    }
    auto base_color = py_util::contiguous<float>(base_color_in, "base_color");
    if (!((base_color.ndim() == 1 && base_color.shape(0) == 3) ||
                         (base_color.ndim() == 2 && base_color.shape(1) == 3))) {
        throw py::value_error("base_color must be one RGB colour (3,) or one per triangle (T, 3)");
    }
    in.base_color = base_color.data();
    in.base_color_count = base_color.ndim() == 1 ? 1 : base_color.shape(0);
    return scene.add_mesh(in);
}

int add_light(Scene& scene, const py::handle& kind_in, const py::kwargs& params) {
    const std::string kind = py_util::string_param(kind_in, "kind");
    Light light;
    if (kind == "point") light.kind = LightKind::Point;
    else if (kind == "spot") light.kind = LightKind::Spot;
    else if (kind == "sun") light.kind = LightKind::Sun;
    else if (kind == "area") light.kind = LightKind::Area;
    else throw py::value_error("light kind must be \"point\", \"spot\", \"sun\" or \"area\", got \"" + kind + "\"");
    if (!params.contains("energy")) {
        throw py::value_error("add_light needs energy= (W, or W/m^2 for a sun), as Blender's light property");
    }
    const py::handle matrix = params.contains("matrix") ? params["matrix"] : py::handle();
    for (const auto& item : params) {
        const std::string key = py::str(item.first);
        const py::handle value = item.second;
        if (matrix && (key == "position" || key == "direction" || key == "axis_x")) {
            throw py::value_error("pass either matrix= or position/direction/axis_x, not both: the matrix "
                                  "already places the light (got matrix and " + key + ")");
        }
        if (key == "energy") light.energy = float(py_util::real_param(value, "energy"));
        else if (key == "color") light.color = vec3_param(value, "color");
        else if (key == "position") light.position = vec3_param(value, "position");
        else if (key == "direction") light.direction = vec3_param(value, "direction");
        else if (key == "axis_x") {
            light.axis_x = vec3_param(value, "axis_x");
            // Zero means "derive it" inside the core; a caller passing zero made a mistake.
            if (light.axis_x == glm::vec3(0.0f)) {
                throw py::value_error("axis_x must not be zero: pass the light's local X axis in world space "
                                      "(Blender: matrix_world column 0), or leave it out for the default");
            }
        }
        else if (key == "matrix") continue;  // applied below, once shape and sizes are known
        else if (key == "shadow_soft_size") light.shadow_soft_size = float(py_util::real_param(value, "shadow_soft_size"));
        else if (key == "angle") light.angle = float(py_util::real_param(value, "angle"));
        else if (key == "spot_size") light.spot_size = float(py_util::real_param(value, "spot_size"));
        else if (key == "spot_blend") light.spot_blend = float(py_util::real_param(value, "spot_blend"));
        else if (key == "shape") light.shape = parse_shape(py_util::string_param(value, "shape"));
        else if (key == "size") light.size = float(py_util::real_param(value, "size"));
        else if (key == "size_y") light.size_y = float(py_util::real_param(value, "size_y"));
        else {
            throw py::value_error("unknown light parameter \"" + key + "\"; use energy, color, position, direction, "
                                  "axis_x, matrix, shadow_soft_size, angle, spot_size, spot_blend, shape, size, "
                                  "size_y");
        }
    }
    if (matrix) place_light(light, matrix_param(matrix));
    return scene.add_light(light);
}

}  // namespace

void bind_scene(py::module_& m) {
    py::class_<Scene, std::shared_ptr<Scene>>(m, "Scene", R"doc(A scene to bake: meshes, lights and a world colour.

World space, transforms applied. Receivers get a lightmap; occluders
(receiver=False) only cast shadows and reflect light. See docs/baker.md.
)doc")
        .def(py::init<>())
        .def("add_mesh", &add_mesh, py::arg("positions"), py::arg("triangles"), py::arg("uvs") = py::none(),
             py::arg("normals") = py::none(), py::arg("base_color") = py::make_tuple(0.8, 0.8, 0.8),
             py::arg("receiver") = py::bool_(true),
             R"doc(Add a triangle mesh; returns its id (0, 1, ...).

Args:
    positions (numpy.ndarray): (V, 3) world-space vertex positions.
    triangles (numpy.ndarray): (T, 3) vertex indices; the winding gives the
        front (lit, baked) side unless normals say otherwise.
    uvs (numpy.ndarray | None): lightmap UVs per corner, (T*3, 2), corner k
        of triangle t at row 3t+k (Blender's loop triangles), inside [0, 1].
        Required for a receiver.
    normals (numpy.ndarray | None): smooth shading normals per corner
        (T*3, 3) or per vertex (V, 3) (if V == T*3 they are read per corner);
        None shades flat.
    base_color: albedo in [0, 1], one RGB for the mesh or (T, 3) per triangle;
        it colours the light the mesh reflects onto others (indirect pass).
    receiver (bool): bake a lightmap for this mesh.

Raises:
    ValueError: NaN/Inf values, indices out of range, UVs outside [0, 1],
        a receiver without UVs, bad shapes. Zero-area triangles are skipped
        and counted (degenerate_triangles).
)doc")
        .def("add_light", &add_light, py::arg("kind"),
             R"doc(Add a light with Blender's property names and units; returns its id.

kind: "point", "spot", "sun" or "area". Keyword parameters: energy (W, or
W/m^2 for a sun; required), color (RGB), shadow_soft_size (point/spot
radius), angle (sun angular diameter, rad), spot_size (cone angle, rad),
spot_blend, shape ("SQUARE", "RECTANGLE", "DISK", "ELLIPSE"), size (along
the light's local X), size_y (along local Y). Defaults are Blender's.

Where the light is, either:
    position (point, spot, area), direction (where it points = its local
        -Z; spot, sun, area; default straight down) and axis_x (its local +X
        in world space; an area light's size runs along it). axis_x is
        made perpendicular to direction (its spin about direction is kept);
        without it the light is oriented as Blender's
        Vector(direction).to_track_quat('-Z', 'Y') (local Y leans to world
        +Z; a light pointing straight down keeps world X and Y).
    or matrix: the light object's 4x4 world matrix (Blender's
        obj.matrix_world), read as Cycles reads it: position = column 3,
        direction = -column 2, axis_x = column 0, and an area light's size
        and size_y scaled by the lengths of columns 0 and 1 (the object's
        scale). Scale does not change point, spot or sun lights (Cycles 3.4).

Spin about direction changes only area lights (rectangles, ellipses):
point and spot lights are round in Cycles 3.4, whatever their scale.

Raises:
    ValueError: unknown kind, shape or parameter; NaN/Inf; zero direction or
        axis_x; axis_x parallel to direction; matrix with zero scale, not
        4x4 or combined with position/direction/axis_x.
)doc")
        .def(
            "set_world",
            [](Scene& scene, const py::handle& color) { scene.set_world(vec3_param(color, "color")); },
            py::arg("color"), "Uniform sky radiance (Blender's world Background colour at strength 1).")
        .def("degenerate_triangles",
             [](const Scene& scene, const py::handle& mesh_in) {
                 const int64_t mesh = py_util::int_param(mesh_in, "mesh", std::numeric_limits<int64_t>::min(),
                                                         std::numeric_limits<int64_t>::max());
                 const int64_t count = int64_t(scene.meshes().size());
                 if (mesh < 0 || mesh >= count) {
                     throw py::value_error(count == 0 ? "mesh must be a mesh id from add_mesh; the scene has no mesh yet"
                                                      : "mesh must be a mesh id from add_mesh, 0 to " +
                                                            std::to_string(count - 1) + ", got " + std::to_string(mesh));
                 }
                 return scene.meshes()[size_t(mesh)].degenerate_count;
             },
             py::arg("mesh"), "Number of zero-area triangles of a mesh (skipped by the baker).")
        .def_property_readonly("mesh_count", [](const Scene& s) { return s.meshes().size(); })
        .def_property_readonly("light_count", [](const Scene& s) { return s.lights().size(); });
}

}  // namespace lmrefine::bindings
