// Primary rays: what a camera sees of the scene (the evaluation's pictures of
// the lit surface). For each ray the closest hit: which mesh and triangle,
// and where on it; shading is left to the caller (a lightmap lookup).
#pragma once

#include <cstdint>
#include <vector>

#include "lmrefine/bake/scene.h"

namespace lmrefine {

class Progress;

struct PrimaryHits {
    std::vector<int32_t> mesh;         // (N) mesh id, -1 where the ray hits nothing
    std::vector<int32_t> triangle;     // (N) triangle of that mesh, -1 on a miss
    std::vector<float> barycentric;    // (N, 2) weights of corners 1 and 2 (corner 0: 1 - sum); 0 on a miss
    std::vector<float> distance;       // (N) hit distance in units of the direction's length; +inf on a miss
};

// Traces `count` rays (origins and directions: (count, 3) each) through the
// scene's meshes, receivers and occluders alike; a direction may have any
// finite length from 1e-28 up. Throws InvalidArgument for a NaN/Inf or
// out-of-scene origin (beyond kMaxCoordinate) or a zero, shorter, NaN or Inf
// direction, naming the ray; Cancelled when `progress` is cancelled.
PrimaryHits trace_primary_rays(const Scene& scene, const float* origins, const float* directions, int64_t count,
                               Progress& progress);

}  // namespace lmrefine
