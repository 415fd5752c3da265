// lmrefine::evaluate (the baker's light at arbitrary points) and the
// benchmark's bare occlusion loop; bake itself is in baker.cpp.
#include "lmrefine/bake/baker.h"

#include <atomic>
#include <cmath>
#include <string>
#include <vector>

#include <glm/geometric.hpp>

#include "bake_passes.h"
#include "lmrefine/core/error.h"
#include "lmrefine/core/parallel.h"
#include "lmrefine/core/progress.h"
#include "ray_tracer.h"
#include "sampler.h"

namespace lmrefine {

EvaluateResult evaluate(const Scene& scene, const float* points, const float* normals, int64_t count,
                        const BakeOptions& options, Progress& progress) {
    const auto started = Clock::now();
    validate_bake_options(scene, options, /*texels=*/false);
    std::vector<SurfacePoint> surface(static_cast<size_t>(count));
    for (int64_t i = 0; i < count; ++i) {
        const glm::vec3 p(points[3 * i], points[3 * i + 1], points[3 * i + 2]);
        const glm::vec3 n(normals[3 * i], normals[3 * i + 1], normals[3 * i + 2]);
        const float length = glm::length(n);
        LMREFINE_REQUIRE(std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z),
                         "points[" + std::to_string(i) + "] is NaN or Inf");
        LMREFINE_REQUIRE(std::abs(p.x) <= kMaxCoordinate && std::abs(p.y) <= kMaxCoordinate &&
                             std::abs(p.z) <= kMaxCoordinate,
                         "points[" + std::to_string(i) + "] has a coordinate beyond +-1e9; pass points in the scene");
        LMREFINE_REQUIRE(std::isfinite(length) && length > 0.0f,
                         "normals[" + std::to_string(i) + "] is zero, NaN or Inf; pass the unit normal of the lit side");
        surface[size_t(i)] = {p, n / length, n / length};
    }
    EvaluateResult result;
    const RayTracer tracer(scene);
    const Integrator integrator(scene, tracer, IntegratorSettings{options.bounces, options.ao_distance});
    std::vector<float> transport[3];
    std::atomic<uint64_t> rays{0};
    for (int tr : kTransports) {
        if (!needed(options.passes, tr)) continue;
        const auto pass_started = Clock::now();
        transport[tr].assign(size_t(count * 3), 0.0f);
        const uint64_t key = hash_combine(hash_combine(options.seed, 0x6576616cull), uint64_t(tr));
        progress.begin(std::string("evaluating ") + kTransportNames[tr], uint64_t(count));
        parallel_for(count, kItemsPerChunk, [&](int64_t begin, int64_t end) {
            uint64_t local_rays = 0;
            SampleSequence sequence;
            for (int64_t i = begin; i < end; ++i) {
                glm::dvec3 sum(0.0);
                sequence.reset(hash_combine(key, uint64_t(i)), uint32_t(options.samples),
                               dimension_count(integrator, tr));
                for (int s = 0; s < options.samples; ++s) {
                    const Sampler sampler(sequence, uint32_t(s));
                    sum += glm::dvec3(estimate(integrator, tr, surface[size_t(i)], sampler, local_rays));
                }
                for (int ch = 0; ch < 3; ++ch) transport[tr][size_t(3 * i + ch)] = float(sum[ch] / options.samples);
            }
            rays.fetch_add(local_rays, std::memory_order_relaxed);
        }, &progress);
        progress.check();
        progress.finish();
        result.stats.pass_seconds.emplace_back(kTransportNames[tr], seconds_since(pass_started));
    }
    for (BakePass pass : options.passes) {
        std::vector<float> values(size_t(count * 3), 0.0f);
        for (int tr : kTransports) {
            if (!contributes(pass, tr)) continue;
            for (size_t i = 0; i < values.size(); ++i) values[i] += transport[tr][i];
        }
        result.passes.push_back(std::move(values));
    }
    result.stats.rays = rays.load();
    result.stats.texels = uint64_t(count);
    result.stats.seconds = seconds_since(started);
    return result;
}

OcclusionLoopResult time_occluded_loop(const Scene& scene, const float* rays, int64_t count) {
    const RayTracer tracer(scene);
    std::atomic<int64_t> occluded{0};
    const auto started = Clock::now();
    parallel_for(count, 4096, [&](int64_t begin, int64_t end) {
        occluded.fetch_add(tracer.occluded_batch(rays, begin, end), std::memory_order_relaxed);
    });
    return {seconds_since(started), occluded.load()};
}

}  // namespace lmrefine
