#include "lmrefine/bake/primary_rays.h"

#include <cmath>
#include <limits>
#include <string>

#include <glm/geometric.hpp>

#include "lmrefine/core/error.h"
#include "lmrefine/core/parallel.h"
#include "lmrefine/core/progress.h"
#include "ray_tracer.h"

namespace lmrefine {

PrimaryHits trace_primary_rays(const Scene& scene, const float* origins, const float* directions, int64_t count,
                               Progress& progress) {
    LMREFINE_REQUIRE(count >= 0, "count must not be negative");
    // Embree aborts on an invalid ray: every ray is checked before any is traced.
    for (int64_t i = 0; i < count; ++i) {
        const float* o = origins + 3 * i;
        const float* d = directions + 3 * i;
        for (int k = 0; k < 3; ++k) {
            LMREFINE_REQUIRE(std::isfinite(o[k]) && std::abs(o[k]) <= kMaxCoordinate,
                             "origins[" + std::to_string(i) + "] is NaN, Inf or beyond +-1e9; put the camera in "
                             "the scene");
            LMREFINE_REQUIRE(std::isfinite(d[k]), "directions[" + std::to_string(i) + "] is NaN or Inf");
        }
        const float length = glm::length(glm::vec3(d[0], d[1], d[2]));
        LMREFINE_REQUIRE(length > 0.0f && std::isfinite(length),
                         "directions[" + std::to_string(i) + "] has zero length; give every ray a direction");
    }
    PrimaryHits hits;
    const size_t n = size_t(count);
    hits.mesh.assign(n, -1);
    hits.triangle.assign(n, -1);
    hits.barycentric.assign(2 * n, 0.0f);
    hits.distance.assign(n, std::numeric_limits<float>::infinity());
    if (count == 0 || scene.meshes().empty()) return hits;
    const RayTracer tracer(scene);
    progress.begin("tracing primary rays", uint64_t(count));
    parallel_for(count, 1024, [&](int64_t begin, int64_t end) {
        for (int64_t i = begin; i < end; ++i) {
            const float* o = origins + 3 * i;
            const float* d = directions + 3 * i;
            Hit hit;
            if (!tracer.intersect({o[0], o[1], o[2]}, {d[0], d[1], d[2]}, std::numeric_limits<float>::infinity(),
                                  hit)) {
                continue;
            }
            const size_t k = size_t(i);
            hits.mesh[k] = hit.mesh;
            hits.triangle[k] = int32_t(hit.triangle);
            hits.barycentric[2 * k] = hit.u;
            hits.barycentric[2 * k + 1] = hit.v;
            hits.distance[k] = hit.t;
        }
    }, &progress);
    progress.check();
    progress.finish();
    return hits;
}

}  // namespace lmrefine
