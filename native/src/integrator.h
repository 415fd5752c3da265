// The light transport of the baker's passes at one surface point (private).
// Values follow Cycles' DIFFUSE bake with the colour pass off: incident
// radiance weighted by cos / pi, i.e. what a white diffuse surface reflects.
#pragma once

#include <cstdint>

#include <glm/vec3.hpp>

#include "ray_tracer.h"
#include "sampler.h"

namespace lmrefine {

class Scene;

struct SurfacePoint {
    glm::vec3 position{0.0f};
    glm::vec3 geometric_normal{0, 0, 1};  // unit; the side that is lit
    glm::vec3 shading_normal{0, 0, 1};    // unit; same side as geometric_normal
};

struct IntegratorSettings {
    int bounces = 4;           // diffuse bounces of the indirect pass (Cycles' default)
    float ao_distance = 10.0f; // occluders farther than this do not count (Blender's default)
};

class Integrator {
public:
    Integrator(const Scene& scene, const RayTracer& tracer, const IntegratorSettings& settings);

    // Lights plus the world, with shadows. `bounce` selects the sample
    // dimensions (0 at the baked point).
    glm::vec3 direct(const SurfacePoint& point, const Sampler& sampler, int bounce, uint64_t& rays) const;
    // Cosine-weighted fraction of the hemisphere open up to ao_distance.
    float ambient_occlusion(const SurfacePoint& point, const Sampler& sampler, uint64_t& rays) const;
    // Light that reached the point after 1..bounces diffuse reflections,
    // each scaled by the base colour where it reflected.
    glm::vec3 indirect(const SurfacePoint& point, const Sampler& sampler, uint64_t& rays) const;

    // Dimension 0 is left to the caller (the sample position in the texel).
    static constexpr uint32_t kFirstDimension = 1;
    // How many sample dimensions the passes use.
    uint32_t dimension_count() const { return dimension(settings_.bounces + 1, 0); }

private:
    // A ray start off the surface on the side `direction` leaves by, so the
    // ray does not hit the surface it starts on.
    glm::vec3 offset(const SurfacePoint& point, const glm::vec3& direction) const;
    uint32_t dimension(int bounce, uint32_t slot) const;
    bool surface_at(const Hit& hit, const glm::vec3& ray_direction, SurfacePoint& point, glm::vec3& albedo) const;

    const Scene& scene_;
    const RayTracer& tracer_;
    IntegratorSettings settings_;
    float offset_floor_;
};

}  // namespace lmrefine
