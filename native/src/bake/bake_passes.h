// What the baker's passes are made of, shared by bake and evaluate (private):
// the light transports (direct, AO, indirect) each traced once per call,
// which of them a pass sums, and the option checks.
#pragma once

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <vector>

#include <glm/vec3.hpp>

#include "integrator.h"
#include "lmrefine/bake/baker.h"

namespace lmrefine {

using Clock = std::chrono::steady_clock;

inline double seconds_since(Clock::time_point start) {
    return std::chrono::duration<double>(Clock::now() - start).count();
}

// A pass is made of light transports, each computed once per bake.
enum Transport { kDirect = 0, kAo = 1, kIndirect = 2 };
inline const char* const kTransportNames[3] = {"direct", "ao", "indirect"};
inline constexpr int kTransports[3] = {kDirect, kAo, kIndirect};

// Whether a transport is part of a requested pass (combined = direct + indirect).
inline bool contributes(BakePass pass, int transport) {
    switch (transport) {
        case kDirect: return pass == BakePass::Direct || pass == BakePass::Combined;
        case kIndirect: return pass == BakePass::Indirect || pass == BakePass::Combined;
        default: return pass == BakePass::AmbientOcclusion;
    }
}

inline bool needed(const std::vector<BakePass>& passes, int transport) {
    return std::any_of(passes.begin(), passes.end(), [&](BakePass p) { return contributes(p, transport); });
}

// One sample of a transport at a surface point.
inline glm::vec3 estimate(const Integrator& integrator, int transport, const SurfacePoint& point,
                          const Sampler& sampler, uint64_t& rays) {
    switch (transport) {
        case kDirect: return integrator.direct(point, sampler, 0, rays);
        case kAo: return glm::vec3(integrator.ambient_occlusion(point, sampler, rays));
        default: return integrator.indirect(point, sampler, rays);
    }
}

// Sample dimensions a transport uses (each costs hashing per texel or point).
inline uint32_t dimension_count(const Integrator& integrator, int transport) {
    return transport == kAo ? Integrator::kAoDimensions : integrator.dimension_count(transport == kIndirect);
}

// Throws InvalidArgument for bad options or a scene with nothing to light;
// `texels`: also the lightmap options (resolution, dilation, receivers).
void validate_bake_options(const Scene& scene, const BakeOptions& options, bool texels);

// Texels or points per parallel work item.
constexpr int64_t kItemsPerChunk = 64;

}  // namespace lmrefine
