// The light transport of the baker's passes at one surface point (private).
// Values follow Cycles' DIFFUSE bake with the colour pass off: incident
// radiance weighted by cos / pi, i.e. what a white diffuse surface reflects.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include <glm/geometric.hpp>
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

// Shadow rays of several samples, traced together (Integrator::direct_rays,
// ao_rays): each adds `value` to its sample when unoccluded.
struct ShadowBatch {
    std::vector<Ray> rays;
    std::vector<glm::vec3> values;
    std::vector<uint32_t> samples;
    std::vector<uint8_t> blocked;

    void clear() {
        rays.clear();
        values.clear();
        samples.clear();
    }
    void add(const Ray& ray, const glm::vec3& value, uint32_t sample) {
        rays.push_back(ray);
        values.push_back(value);
        samples.push_back(sample);
    }
};

class Integrator {
public:
    Integrator(const Scene& scene, const RayTracer& tracer, const IntegratorSettings& settings);

    // Lights plus the world, with shadows. `bounce` selects the sample
    // dimensions (0 at the baked point).
    glm::vec3 direct(const SurfacePoint& point, const Sampler& sampler, int bounce, uint64_t& rays) const;
    // Cosine-weighted fraction of the hemisphere open up to ao_distance.
    float ambient_occlusion(const SurfacePoint& point, const Sampler& sampler, uint64_t& rays) const;
    // The same two estimates as shadow rays of sample `sample`, appended to
    // `batch` (or `ray`) to be traced later: direct() and ambient_occlusion()
    // equal the sum of the values of a sample's unoccluded rays.
    void direct_rays(const SurfacePoint& point, const Sampler& sampler, uint32_t sample, ShadowBatch& batch) const;
    // AO's ray is worth 1 when unoccluded: no value or sample to record.
    bool ao_ray(const SurfacePoint& point, const Sampler& sampler, Ray& ray) const {
        return hemisphere_ray(point, sampler, 0, settings_.ao_distance, ray);
    }
    // Light that reached the point after 1..bounces diffuse reflections,
    // each scaled by the base colour where it reflected.
    glm::vec3 indirect(const SurfacePoint& point, const Sampler& sampler, uint64_t& rays) const;

    // Dimension 0 is left to the caller (the sample position in the texel).
    static constexpr uint32_t kFirstDimension = 1;
    // How many sample dimensions a transport uses: direct light and AO only
    // those of the baked point; indirect light those of every bounce.
    uint32_t dimension_count(bool bounces) const { return dimension(bounces ? settings_.bounces + 1 : 1, 0); }
    // AO uses the sample position and the hemisphere direction only.
    static constexpr uint32_t kAoDimensions = kFirstDimension + 1;

private:
    // A ray start off the surface on the side `direction` leaves by, so the
    // ray does not hit the surface it starts on. The offset scales with the
    // coordinates' magnitude: float spacing grows with it.
    glm::vec3 offset(const SurfacePoint& point, const glm::vec3& direction) const {
        const glm::vec3& p = point.position;
        const float magnitude = std::max({std::abs(p.x), std::abs(p.y), std::abs(p.z), offset_floor_});
        const float side = glm::dot(direction, point.geometric_normal) >= 0.0f ? 1.0f : -1.0f;
        return p + point.geometric_normal * (side * 1e-5f * magnitude);
    }
    // Per bounce: the world/AO direction, the bounce direction, one per light.
    uint32_t dimension(int bounce, uint32_t slot) const {
        return kFirstDimension + uint32_t(bounce) * (2 + light_count_) + slot;
    }
    // The shadow ray towards light `light` (false if it cannot reach the point).
    bool light_ray(const SurfacePoint& point, const Sampler& sampler, int bounce, size_t light, Ray& ray,
                   glm::vec3& value) const;
    // The cosine-sampled ray towards the sky, of length `tfar` (false if it
    // leaves below the geometric surface).
    bool hemisphere_ray(const SurfacePoint& point, const Sampler& sampler, int bounce, float tfar, Ray& ray) const;
    bool surface_at(const Hit& hit, const glm::vec3& ray_direction, SurfacePoint& point, glm::vec3& albedo) const;

    const Scene& scene_;
    const RayTracer& tracer_;
    IntegratorSettings settings_;
    float offset_floor_;
    uint32_t light_count_;
};

}  // namespace lmrefine
