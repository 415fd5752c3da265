// Which triangles lie behind each lightmap texel, and where a sample in a
// texel lands on the surface (private to the baker).
#pragma once

#include <cstdint>
#include <vector>

#include <glm/vec2.hpp>
#include <glm/vec3.hpp>

#include "integrator.h"

namespace lmrefine {

class Scene;

struct TexelTable {
    int width = 0, height = 0;
    std::vector<int64_t> texels;         // covered texel indices (row * width + col), ascending
    std::vector<int64_t> offsets;        // texels.size() + 1; candidates of texel k: [offsets[k], offsets[k+1])
    std::vector<int32_t> candidate_mesh;
    std::vector<int64_t> candidate_triangle;
    std::vector<int32_t> texel_chart;    // (height * width) chart id or -1 (charts numbered across the map's meshes)
    std::vector<int32_t> near_chart;     // (height * width) NearCharts' chart of a gutter texel, or -1
};

// Conservative rasterization (for_each_covered_texel) of the UV layouts of
// `meshes` at width x height, skipping zero-area triangles.
TexelTable build_texel_table(const Scene& scene, const std::vector<int>& meshes, int width, int height);

// The surfaces behind one texel, prepared once so that each sample costs a
// few multiply-adds: sample positions (continuous pixel coordinates) map to
// the candidate triangle that contains them, or else to the nearest one with
// the point clamped just inside it (a texel that a chart covers only partly).
class TexelGeometry {
public:
    void load(const Scene& scene, const TexelTable& table, int64_t k);
    SurfacePoint at(double px, double py) const;
    // World-space edge length of a texel on the first candidate triangle.
    float texel_size() const { return texel_size_; }

private:
    struct Candidate {
        glm::dvec3 wx, wy, w0;  // barycentrics = wx * px + wy * py + w0
        glm::dvec2 corner[3];   // pixel space
        glm::vec3 position[3];
        glm::vec3 normal[3];    // shading normals (the geometric one if flat)
        glm::vec3 geometric_normal;
        bool smooth;
    };
    SurfacePoint point_on(const Candidate& c, const glm::dvec3& weights) const;
    // How far (in texels) a clamped sample moves off the border line, towards
    // its triangle's centre: float noise in positions is far below it.
    static constexpr double kInset = 1.0 / 64.0;

    std::vector<Candidate> candidates_;
    float texel_size_ = 0.0f;
};

}  // namespace lmrefine
