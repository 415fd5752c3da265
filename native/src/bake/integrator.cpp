#include "integrator.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <glm/geometric.hpp>

#include "lmrefine/bake/scene.h"

namespace lmrefine {
namespace {

constexpr float kPi = 3.14159265358979f;
constexpr float kInfinity = std::numeric_limits<float>::infinity();

// sin and cos of 2 pi t for t in [0, 1): a reduction to [-pi/4, pi/4] and
// Taylor polynomials (error < 1e-7, float precision), cheaper than libm's
// sincosf (docs/baker.md, "Speed").
void sincos_turn(float t, float& s, float& c) {
    const float q = t * 4.0f;
    const int k = int(q + 0.5f);  // the nearest quarter turn (t >= 0)
    const float x = (q - float(k)) * (0.5f * kPi), x2 = x * x;
    const float sx = x * (1.0f + x2 * (-1.0f / 6 + x2 * (1.0f / 120 + x2 * (-1.0f / 5040 + x2 * (1.0f / 362880)))));
    const float cx = 1.0f + x2 * (-0.5f + x2 * (1.0f / 24 + x2 * (-1.0f / 720 + x2 * (1.0f / 40320))));
    switch (k & 3) {  // rotate by k quarter turns
        case 0: s = sx; c = cx; break;
        case 1: s = cx; c = -sx; break;
        case 2: s = -sx; c = -cx; break;
        default: s = -cx; c = sx; break;
    }
}

glm::vec3 cosine_hemisphere(const glm::vec3& n, const glm::vec2& u) {
    const float r = std::sqrt(u.x);
    float sin_phi, cos_phi;
    sincos_turn(u.y, sin_phi, cos_phi);
    const float sign = std::copysign(1.0f, n.z);
    const float a = -1.0f / (sign + n.z);
    const float b = n.x * n.y * a;
    const glm::vec3 x(1.0f + sign * n.x * n.x * a, sign * b, -sign * n.x), y(b, sign + n.y * n.y * a, -n.y);
    // (x, y, n) is orthonormal, so the result is unit length without normalizing.
    return x * (r * cos_phi) + y * (r * sin_phi) + n * std::sqrt(std::max(0.0f, 1.0f - u.x));
}

}  // namespace

Integrator::Integrator(const Scene& scene, const RayTracer& tracer, const IntegratorSettings& settings)
    : scene_(scene),
      tracer_(tracer),
      settings_(settings),
      offset_floor_(0.05f * std::max(scene.extent(), 1e-6f)),
      light_count_(uint32_t(scene.lights().size())) {}

bool Integrator::light_ray(const SurfacePoint& point, const Sampler& sampler, int bounce, size_t light, Ray& ray,
                           glm::vec3& value) const {
    LightSample s;
    if (!sample_light(scene_.lights()[light], point.position, sampler.get(dimension(bounce, 2 + uint32_t(light))), s)) {
        return false;
    }
    const float cos_theta = glm::dot(point.shading_normal, s.direction);
    // Light from below the shading or geometric surface does not reach it.
    if (cos_theta <= 0.0f || glm::dot(point.geometric_normal, s.direction) <= 0.0f) return false;
    ray.origin = offset(point, s.direction);
    ray.direction = s.direction;
    // Stop just short of the light sample.
    ray.tfar = std::isinf(s.distance)
                   ? kInfinity
                   : glm::length(point.position + s.direction * s.distance - ray.origin) * (1.0f - 1e-4f);
    value = s.value * cos_theta;
    return true;
}

bool Integrator::hemisphere_ray(const SurfacePoint& point, const Sampler& sampler, int bounce, float tfar,
                                Ray& ray) const {
    ray.direction = cosine_hemisphere(point.shading_normal, sampler.get(dimension(bounce, 0)));
    if (glm::dot(point.geometric_normal, ray.direction) <= 0.0f) return false;
    ray.origin = offset(point, ray.direction);
    ray.tfar = tfar;
    return true;
}

glm::vec3 Integrator::direct(const SurfacePoint& point, const Sampler& sampler, int bounce, uint64_t& rays) const {
    glm::vec3 sum(0.0f), value;
    Ray ray;
    for (size_t i = 0; i < scene_.lights().size(); ++i) {
        if (!light_ray(point, sampler, bounce, i, ray, value)) continue;
        ++rays;
        if (!tracer_.occluded(ray.origin, ray.direction, ray.tfar)) sum += value;
    }
    // Cosine sampling of a uniform sky: the estimate is the sky colour where open.
    if (scene_.has_world() && hemisphere_ray(point, sampler, bounce, kInfinity, ray)) {
        ++rays;
        if (!tracer_.occluded(ray.origin, ray.direction, ray.tfar)) sum += scene_.world();
    }
    return sum;
}

void Integrator::direct_rays(const SurfacePoint& point, const Sampler& sampler, uint32_t sample,
                             ShadowBatch& batch) const {
    glm::vec3 value;
    Ray ray;
    for (size_t i = 0; i < scene_.lights().size(); ++i) {
        if (light_ray(point, sampler, 0, i, ray, value)) batch.add(ray, value, sample);
    }
    if (scene_.has_world() && hemisphere_ray(point, sampler, 0, kInfinity, ray)) batch.add(ray, scene_.world(), sample);
}

float Integrator::ambient_occlusion(const SurfacePoint& point, const Sampler& sampler, uint64_t& rays) const {
    Ray ray;
    if (!hemisphere_ray(point, sampler, 0, settings_.ao_distance, ray)) return 0.0f;
    ++rays;
    return tracer_.occluded(ray.origin, ray.direction, ray.tfar) ? 0.0f : 1.0f;
}

bool Integrator::surface_at(const Hit& hit, const glm::vec3& ray_direction, SurfacePoint& point,
                            glm::vec3& albedo) const {
    const Mesh& mesh = scene_.meshes()[size_t(hit.mesh)];
    if (mesh.degenerate[size_t(hit.triangle)]) return false;
    const int32_t* v = &mesh.triangles[size_t(3 * hit.triangle)];
    const float w = 1.0f - hit.u - hit.v;
    const glm::vec3 &a = mesh.positions[v[0]], &b = mesh.positions[v[1]], &c = mesh.positions[v[2]];
    point.position = a * w + b * hit.u + c * hit.v;
    glm::vec3 ng = glm::normalize(glm::cross(b - a, c - a));
    // Surfaces hit by a bounce are two-sided, as in Cycles: face the ray.
    if (glm::dot(ng, ray_direction) > 0.0f) ng = -ng;
    point.geometric_normal = ng;
    point.shading_normal = ng;
    if (!mesh.normals.empty()) {
        const glm::vec3* n = &mesh.normals[size_t(3 * hit.triangle)];
        glm::vec3 ns = n[0] * w + n[1] * hit.u + n[2] * hit.v;
        const float length = glm::length(ns);
        if (length > 0.0f) {
            ns /= length;
            point.shading_normal = glm::dot(ns, ng) >= 0.0f ? ns : -ns;
        }
    }
    albedo = mesh.base_color[size_t(hit.triangle)];
    return true;
}

glm::vec3 Integrator::indirect(const SurfacePoint& start, const Sampler& sampler, uint64_t& rays) const {
    glm::vec3 sum(0.0f), throughput(1.0f);
    SurfacePoint point = start;
    for (int bounce = 1; bounce <= settings_.bounces; ++bounce) {
        // Cosine sampling cancels the cos / pi of the diffuse reflection.
        const glm::vec3 d = cosine_hemisphere(point.shading_normal, sampler.get(dimension(bounce - 1, 1)));
        if (glm::dot(point.geometric_normal, d) <= 0.0f) break;
        Hit hit;
        ++rays;
        if (!tracer_.intersect(offset(point, d), d, kInfinity, hit)) break;  // the sky is direct light
        glm::vec3 albedo;
        if (!surface_at(hit, d, point, albedo)) break;
        throughput *= albedo;
        if (throughput.x <= 0.0f && throughput.y <= 0.0f && throughput.z <= 0.0f) break;
        sum += throughput * direct(point, sampler, bounce, rays);
    }
    return sum;
}

}  // namespace lmrefine
