// Which triangles lie behind each lightmap texel, and where a sample in a
// texel lands on the surface (private to the baker).
#pragma once

#include <cstdint>
#include <vector>

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
};

// Conservative rasterization (for_each_covered_texel) of the UV layouts of
// `meshes` at width x height, skipping zero-area triangles.
TexelTable build_texel_table(const Scene& scene, const std::vector<int>& meshes, int width, int height);

// The surface point under `pixel` (continuous pixel coordinates inside texel
// `k`): the candidate triangle that contains it, or else the nearest one with
// the point clamped onto it (a texel that a chart covers only partly).
// Also returns the world-space edge length of a texel there.
SurfacePoint texel_surface_point(const Scene& scene, const TexelTable& table, int64_t k, double px, double py,
                                 float* texel_size = nullptr);

}  // namespace lmrefine
