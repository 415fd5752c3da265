// The Embree 3 scene behind the baker (private: only ray_tracer.cpp includes
// embree3). Embree's errors arrive through rtcSetDeviceErrorFunction and are
// thrown as lmrefine errors after the call that raised them.
#pragma once

#include <cstdint>
#include <memory>

#include <glm/vec3.hpp>

namespace lmrefine {

class Scene;

struct Ray {
    glm::vec3 origin{0.0f};
    glm::vec3 direction{0.0f};
    float tfar = 0.0f;
};

struct Hit {
    int mesh = -1;
    int64_t triangle = -1;
    float u = 0.0f, v = 0.0f;  // barycentrics of corners 1 and 2
    float t = 0.0f;            // distance along the ray, in units of |direction|
};

class RayTracer {
public:
    explicit RayTracer(const Scene& scene);
    ~RayTracer();
    RayTracer(const RayTracer&) = delete;
    RayTracer& operator=(const RayTracer&) = delete;

    // True if anything lies along origin + t * direction, t in (0, tfar).
    bool occluded(const glm::vec3& origin, const glm::vec3& direction, float tfar) const;
    // blocked[i] = occluded(rays[i]), traced in packets of 8: pass rays that
    // start close together and are in a sensible order (a texel's rays).
    void occluded(const Ray* rays, size_t count, uint8_t* blocked) const;
    // The closest hit along the ray, if any.
    bool intersect(const glm::vec3& origin, const glm::vec3& direction, float tfar, Hit& hit) const;

    // A bare loop of occlusion rays (the benchmark's baseline): returns the
    // number of occluded rays. Rays are (origin, direction, tfar) rows of 7 floats.
    int64_t occluded_batch(const float* rays, int64_t begin, int64_t end) const;

    struct Impl;  // public so Embree's C error callback can reach it

private:
    std::unique_ptr<Impl> impl_;
};

}  // namespace lmrefine
