#include "lmrefine/bake/scene.h"

#include <algorithm>
#include <cmath>
#include <string>

#include <glm/geometric.hpp>

#include "lmrefine/core/error.h"

namespace lmrefine {
namespace {

std::string mesh_name(size_t id) { return "mesh " + std::to_string(id) + ": "; }

void require_finite(const float* values, int64_t count, int columns, const std::string& where, const char* name) {
    for (int64_t i = 0; i < count * columns; ++i) {
        if (!std::isfinite(values[i])) {
            LMREFINE_THROW(InvalidArgument, where + name + "[" + std::to_string(i / columns) +
                                                "] is NaN or Inf; fix or remove the broken geometry");
        }
    }
}

// Zero-area test relative to the triangle's own edge lengths, so it does not
// depend on the scene's units.
bool is_degenerate(const glm::vec3& a, const glm::vec3& b, const glm::vec3& c) {
    const glm::vec3 e1 = b - a, e2 = c - a;
    const float area2 = glm::length(glm::cross(e1, e2));
    const float scale = std::max({glm::dot(e1, e1), glm::dot(e2, e2), glm::dot(c - b, c - b)});
    return !(area2 > 1e-7f * scale);
}

}  // namespace

void Scene::check_not_read(const char* what) const {
    if (readers_.load() > 0) {
        LMREFINE_THROW(InvalidArgument, std::string("cannot ") + what +
                                            " while the scene is being baked, evaluated or traced (from its progress "
                                            "callback or another thread): add everything before the call, or after "
                                            "it returns");
    }
}

int Scene::add_mesh(const MeshInput& in) {
    check_not_read("add a mesh");
    const std::string where = mesh_name(meshes_.size());
    LMREFINE_REQUIRE(in.vertex_count > 0 && in.triangle_count > 0, where + "positions and triangles must not be empty");
    LMREFINE_REQUIRE(in.base_color_count == 1 || in.base_color_count == in.triangle_count,
                     where + "base_color must be one RGB colour or one per triangle (T, 3), got " +
                         std::to_string(in.base_color_count) + " colours for " +
                         std::to_string(in.triangle_count) + " triangles");
    require_finite(in.positions, in.vertex_count, 3, where, "positions");
    for (int64_t i = 0; i < in.vertex_count * 3; ++i) {
        if (std::abs(in.positions[i]) > kMaxCoordinate) {
            LMREFINE_THROW(InvalidArgument, where + "positions[" + std::to_string(i / 3) + "] has a coordinate of " +
                                                std::to_string(in.positions[i]) + ", beyond +-1e9; fix the broken "
                                                "vertex or scale the scene down");
        }
    }
    Mesh mesh;
    mesh.receiver = in.receiver;
    mesh.positions.resize(size_t(in.vertex_count));
    for (int64_t i = 0; i < in.vertex_count; ++i) {
        mesh.positions[i] = {in.positions[3 * i], in.positions[3 * i + 1], in.positions[3 * i + 2]};
        extent_ = std::max({extent_, std::abs(mesh.positions[i].x), std::abs(mesh.positions[i].y),
                            std::abs(mesh.positions[i].z)});
    }
    mesh.triangles.assign(in.triangles, in.triangles + in.triangle_count * 3);
    for (int64_t i = 0; i < in.triangle_count * 3; ++i) {
        if (mesh.triangles[i] < 0 || mesh.triangles[i] >= in.vertex_count) {
            LMREFINE_THROW(InvalidArgument, where + "triangles[" + std::to_string(i / 3) + "] refers to vertex " +
                                                std::to_string(mesh.triangles[i]) + ", but there are only " +
                                                std::to_string(in.vertex_count) + " positions");
        }
    }
    if (in.receiver) {
        LMREFINE_REQUIRE(in.uvs != nullptr, where + "a receiver needs lightmap uvs (T*3, 2) per corner; "
                                                    "pass uvs=... or add it with receiver=False (occluder only)");
    }
    if (in.uvs) {
        const int64_t corners = in.triangle_count * 3;
        require_finite(in.uvs, corners, 2, where, "uvs");
        for (int64_t i = 0; i < corners * 2; ++i) {
            if (in.uvs[i] < 0.0f || in.uvs[i] > 1.0f) {
                LMREFINE_THROW(InvalidArgument,
                               where + "uvs[" + std::to_string(i / 2) + "] = (" + std::to_string(in.uvs[i & ~int64_t(1)]) +
                                   ", " + std::to_string(in.uvs[i | 1]) +
                                   ") is outside [0, 1]; a lightmap layout must lie inside the unit square "
                                   "(pack the lightmap UVs first)");
            }
        }
        mesh.uvs.resize(size_t(corners));
        for (int64_t i = 0; i < corners; ++i) mesh.uvs[i] = {in.uvs[2 * i], in.uvs[2 * i + 1]};
    }
    if (in.normals) {
        const bool per_corner = in.normal_count == in.triangle_count * 3;
        LMREFINE_REQUIRE(per_corner || in.normal_count == in.vertex_count,
                         where + "normals must be per corner (T*3, 3) or per vertex (V, 3), got " +
                             std::to_string(in.normal_count) + " rows for " + std::to_string(in.triangle_count) +
                             " triangles and " + std::to_string(in.vertex_count) + " vertices");
        require_finite(in.normals, in.normal_count, 3, where, "normals");
        mesh.normals.resize(size_t(in.triangle_count * 3));
        for (int64_t c = 0; c < in.triangle_count * 3; ++c) {
            const int64_t row = per_corner ? c : mesh.triangles[c];
            const glm::vec3 n(in.normals[3 * row], in.normals[3 * row + 1], in.normals[3 * row + 2]);
            const float length = glm::length(n);
            LMREFINE_REQUIRE(length > 0.0f, where + "normals[" + std::to_string(row) + "] is zero; "
                                                    "pass unit normals or omit them for flat shading");
            mesh.normals[c] = n / length;
        }
    }
    require_finite(in.base_color, in.base_color_count, 3, where, "base_color");
    mesh.base_color.resize(size_t(in.triangle_count));
    for (int64_t t = 0; t < in.triangle_count; ++t) {
        const float* c = in.base_color + 3 * (in.base_color_count == 1 ? 0 : t);
        for (int k = 0; k < 3; ++k) {
            LMREFINE_REQUIRE(c[k] >= 0.0f && c[k] <= 1.0f,
                             where + "base_color of triangle " + std::to_string(t) +
                                 " is outside [0, 1]; an albedo above 1 would create energy");
        }
        mesh.base_color[t] = {c[0], c[1], c[2]};
    }
    mesh.degenerate.resize(size_t(in.triangle_count));
    for (int64_t t = 0; t < in.triangle_count; ++t) {
        const int32_t* v = &mesh.triangles[3 * t];
        mesh.degenerate[t] = is_degenerate(mesh.positions[v[0]], mesh.positions[v[1]], mesh.positions[v[2]]);
        mesh.degenerate_count += mesh.degenerate[t];
    }
    meshes_.push_back(std::move(mesh));
    return int(meshes_.size() - 1);
}

int Scene::add_light(Light light) {
    check_not_read("add a light");
    validate_light(light);
    lights_.push_back(light);
    return int(lights_.size() - 1);
}

void Scene::set_world(const glm::vec3& color) {
    check_not_read("set the world colour");
    for (int k = 0; k < 3; ++k) {
        LMREFINE_REQUIRE(std::isfinite(color[k]) && color[k] >= 0.0f,
                         "world colour must be finite and >= 0 (it is the sky's radiance)");
    }
    world_ = color;
}

}  // namespace lmrefine
