// The scene the baker renders: triangle meshes with per-corner lightmap UVs,
// lights in Blender's units and a uniform world colour. Transforms are
// already applied (world space). The scene owns copies of its arrays.
#pragma once

#include <atomic>
#include <cstdint>
#include <vector>

#include <glm/vec2.hpp>
#include <glm/vec3.hpp>

#include "lmrefine/bake/lights.h"

namespace lmrefine {

// Largest coordinate a position (or a point given to evaluate) may have. Rays
// start at float positions offset relative to the scene's size: beyond this
// a scene loses all precision, and near 1e18 Embree rejects the ray.
constexpr float kMaxCoordinate = 1e9f;

struct Mesh {
    std::vector<glm::vec3> positions;    // (V)
    std::vector<int32_t> triangles;      // (T * 3) indices into positions
    std::vector<glm::vec2> uvs;          // (T * 3) per corner, corner k of triangle t at 3t + k; receivers only
    std::vector<glm::vec3> normals;      // (T * 3) per corner, unit; empty = flat shading
    std::vector<glm::vec3> base_color;   // (T) albedo per triangle, in [0, 1]
    std::vector<uint8_t> degenerate;     // (T) 1 for a zero-area triangle (skipped)
    int64_t degenerate_count = 0;
    bool receiver = true;

    int64_t triangle_count() const { return int64_t(triangles.size() / 3); }
};

// Views of caller arrays for add_mesh; the scene copies them.
struct MeshInput {
    const float* positions = nullptr;  // (vertex_count, 3)
    int64_t vertex_count = 0;
    const int32_t* triangles = nullptr;  // (triangle_count, 3)
    int64_t triangle_count = 0;
    const float* uvs = nullptr;  // (triangle_count * 3, 2) per corner, or null
    const float* normals = nullptr;  // (normal_count, 3), or null
    int64_t normal_count = 0;        // triangle_count * 3 (per corner) or vertex_count (per vertex)
    const float* base_color = nullptr;  // (base_color_count, 3)
    int64_t base_color_count = 0;       // 1 (whole mesh) or triangle_count
    bool receiver = true;
};

class Scene {
public:
    // Validates and copies the mesh; returns its id (0, 1, ...). Throws
    // InvalidArgument naming the first bad value: NaN/Inf positions (or
    // beyond kMaxCoordinate) or
    // normals, indices out of range, receiver without UVs, UVs outside [0, 1],
    // base colours outside [0, 1]. Zero-area triangles are kept (their index
    // stays valid) but skipped by the baker and counted in degenerate_count.
    int add_mesh(const MeshInput& input);
    // Validates the light (validate_light); returns its id.
    int add_light(Light light);
    void set_world(const glm::vec3& color);

    // While a bake, an evaluate or a ray query reads the scene (its progress
    // callback runs Python, and another thread may hold the scene too), adding
    // to it would reallocate the arrays being read: add_mesh, add_light and
    // set_world throw InvalidArgument then. A reader holds a Reading.
    class Reading {
    public:
        explicit Reading(const Scene& scene) : scene_(scene) { ++scene_.readers_; }
        ~Reading() { --scene_.readers_; }
        Reading(const Reading&) = delete;
        Reading& operator=(const Reading&) = delete;

    private:
        const Scene& scene_;
    };

    const std::vector<Mesh>& meshes() const { return meshes_; }
    const std::vector<Light>& lights() const { return lights_; }
    const glm::vec3& world() const { return world_; }
    bool has_world() const { return world_.x > 0 || world_.y > 0 || world_.z > 0; }
    // Largest absolute coordinate of any vertex: the scale for ray offsets.
    float extent() const { return extent_; }

private:
    void check_not_read(const char* what) const;

    mutable std::atomic<int> readers_{0};
    std::vector<Mesh> meshes_;
    std::vector<Light> lights_;
    glm::vec3 world_{0.0f};
    float extent_ = 0.0f;
};

}  // namespace lmrefine
