#include "lmrefine/bake/primary_rays.h"

#include <cmath>
#include <cstdio>
#include <limits>
#include <string>

#include <glm/geometric.hpp>

#include "lmrefine/core/error.h"
#include "lmrefine/core/parallel.h"
#include "lmrefine/core/progress.h"
#include "ray_tracer.h"

namespace lmrefine {
namespace {

// Embree's traversal takes a direction component below 1e-18 as 1e-18, so a
// tiny direction drifts sideways along its long ray parameter (a silent miss),
// and the tracer skips one with a component past 1e18 (ray_tracer.cpp). A
// direction whose length is outside [2^-20, 2^20] is traced scaled by 2^e to
// a length in [1, 2) (exact), and its distance scaled back by 2^e; this
// returns e, 0 for the others (traced as given).
// The shortest direction traced: the farthest hit inside the scene's +-1e9
// (kMaxCoordinate) is 3.5e9 away, 3.5e37 of these lengths: float32 holds it.
constexpr double kMinLength = 1e-28;

int scale_exponent(const float* d) {
    const double length = std::sqrt(double(d[0]) * d[0] + double(d[1]) * d[1] + double(d[2]) * d[2]);
    if (length >= 0x1p-20 && length <= 0x1p20) return 0;
    return -std::ilogb(length);
}

}  // namespace

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
            LMREFINE_REQUIRE(std::isfinite(d[k]), "directions[" + std::to_string(i) + "] is NaN or Inf (a float32 "
                             "beyond 3.4e38 is Inf); give every ray a finite direction, of any length");
        }
        const double length = std::sqrt(double(d[0]) * d[0] + double(d[1]) * d[1] + double(d[2]) * d[2]);
        LMREFINE_REQUIRE(length > 0.0, "directions[" + std::to_string(i) + "] has zero length; give every ray a "
                                       "direction");
        if (length < kMinLength) {
            char text[32];
            std::snprintf(text, sizeof text, "%.3g", length);
            LMREFINE_THROW(InvalidArgument, "directions[" + std::to_string(i) + "] has length " + text + ", too short: "
                                                "a hit's distance, in units of the length, would pass float32's "
                                                "3.4e38; scale it towards length 1 (only the direction counts)");
        }
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
            const int exponent = scale_exponent(d);
            const glm::vec3 direction(std::ldexp(d[0], exponent), std::ldexp(d[1], exponent),
                                      std::ldexp(d[2], exponent));
            Hit hit;
            if (!tracer.intersect({o[0], o[1], o[2]}, direction, std::numeric_limits<float>::infinity(), hit)) {
                continue;
            }
            const size_t k = size_t(i);
            hits.mesh[k] = hit.mesh;
            hits.triangle[k] = int32_t(hit.triangle);
            hits.barycentric[2 * k] = hit.u;
            hits.barycentric[2 * k + 1] = hit.v;
            hits.distance[k] = exponent == 0 ? hit.t : float(std::ldexp(double(hit.t), exponent));
        }
    }, &progress);
    progress.check();
    progress.finish();
    return hits;
}

}  // namespace lmrefine
