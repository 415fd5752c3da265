#include "ray_tracer.h"

#include <embree3/rtcore.h>

#include <cmath>
#include <limits>
#include <mutex>
#include <string>

#include "lmrefine/core/error.h"
#include "lmrefine/bake/scene.h"

namespace lmrefine {

struct RayTracer::Impl {
    RTCDevice device = nullptr;
    RTCScene scene = nullptr;
    std::mutex error_mutex;
    std::string error;  // first error Embree reported
    RTCError error_code = RTC_ERROR_NONE;

    void throw_if_failed(const char* what) {
        std::lock_guard<std::mutex> lock(error_mutex);
        if (error.empty()) return;
        const std::string message = std::string("Embree failed while ") + what + ": " + error;
        if (error_code == RTC_ERROR_OUT_OF_MEMORY) LMREFINE_THROW(ResourceError, message);
        LMREFINE_THROW(Error, message);
    }

    ~Impl() {
        if (scene) rtcReleaseScene(scene);
        if (device) rtcReleaseDevice(device);
    }
};

namespace {

void on_embree_error(void* user, RTCError code, const char* message) {
    auto* impl = static_cast<RayTracer::Impl*>(user);
    std::lock_guard<std::mutex> lock(impl->error_mutex);
    if (impl->error.empty()) {
        impl->error = message ? message : "unknown error";
        impl->error_code = code;
    }
}

// What Embree asserts on (RayK::valid): finite origin and direction below
// ~1.8e18, tnear and tfar not NaN. Scene and points are checked where they
// come in; this guard keeps any ray that still slips through (a light placed
// absurdly far, a sliver triangle's NaN normal) from aborting the process:
// it is not traced, and counts as blocked (no light along it).
constexpr float kEmbreeLarge = 1e18f;
bool ray_valid(const glm::vec3& origin, const glm::vec3& direction, float tfar) {
    for (int k = 0; k < 3; ++k) {
        if (!(std::abs(origin[k]) <= kEmbreeLarge) || !(std::abs(direction[k]) <= kEmbreeLarge)) return false;
    }
    return tfar >= 0.0f;  // false for NaN; +inf is fine
}

RTCRay make_ray(const glm::vec3& origin, const glm::vec3& direction, float tfar) {
    RTCRay ray;
    ray.org_x = origin.x;
    ray.org_y = origin.y;
    ray.org_z = origin.z;
    ray.dir_x = direction.x;
    ray.dir_y = direction.y;
    ray.dir_z = direction.z;
    ray.tnear = 0.0f;
    ray.tfar = tfar;
    ray.time = 0.0f;
    ray.mask = 0xFFFFFFFFu;
    ray.id = 0;
    ray.flags = 0;
    return ray;
}

}  // namespace

RayTracer::RayTracer(const Scene& scene) : impl_(std::make_unique<Impl>()) {
    impl_->device = rtcNewDevice(nullptr);
    if (!impl_->device) {
        LMREFINE_THROW(Error, "Embree could not create a device (error " +
                                  std::to_string(int(rtcGetDeviceError(nullptr))) + ")");
    }
    rtcSetDeviceErrorFunction(impl_->device, on_embree_error, impl_.get());
    impl_->scene = rtcNewScene(impl_->device);
    rtcSetSceneFlags(impl_->scene, RTC_SCENE_FLAG_ROBUST);
    rtcSetSceneBuildQuality(impl_->scene, RTC_BUILD_QUALITY_HIGH);
    const auto& meshes = scene.meshes();
    for (size_t id = 0; id < meshes.size(); ++id) {
        const Mesh& mesh = meshes[id];
        RTCGeometry geometry = rtcNewGeometry(impl_->device, RTC_GEOMETRY_TYPE_TRIANGLE);
        auto* vertices = static_cast<float*>(rtcSetNewGeometryBuffer(
            geometry, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), mesh.positions.size()));
        auto* indices = static_cast<uint32_t*>(rtcSetNewGeometryBuffer(
            geometry, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(uint32_t), size_t(mesh.triangle_count())));
        impl_->throw_if_failed("allocating geometry");
        for (size_t i = 0; i < mesh.positions.size(); ++i) {
            vertices[3 * i] = mesh.positions[i].x;
            vertices[3 * i + 1] = mesh.positions[i].y;
            vertices[3 * i + 2] = mesh.positions[i].z;
        }
        for (size_t i = 0; i < mesh.triangles.size(); ++i) indices[i] = uint32_t(mesh.triangles[i]);
        rtcCommitGeometry(geometry);
        rtcAttachGeometryByID(impl_->scene, geometry, unsigned(id));
        rtcReleaseGeometry(geometry);
    }
    rtcCommitScene(impl_->scene);
    impl_->throw_if_failed("building the scene");
}

RayTracer::~RayTracer() = default;

bool RayTracer::occluded(const glm::vec3& origin, const glm::vec3& direction, float tfar) const {
    RTCIntersectContext context;
    rtcInitIntersectContext(&context);
    if (!ray_valid(origin, direction, tfar)) return true;
    RTCRay ray = make_ray(origin, direction, tfar);
    rtcOccluded1(impl_->scene, &context, &ray);
    return ray.tfar < 0.0f;  // Embree sets tfar to -inf on a hit
}

namespace {

// Packets of 8 (AVX2's width): a texel's rays start close together, and
// Embree traverses a packet's shared nodes once (widths compared in
// docs/baker.md, "Speed").
template <int N> struct Packet;
template <> struct Packet<8> {
    using Rays = RTCRay8;
    static void occluded(const int* valid, RTCScene scene, RTCIntersectContext* context, Rays* rays) {
        rtcOccluded8(valid, scene, context, rays);
    }
};
template <int N>
void occluded_packets(RTCScene scene, const Ray* rays, size_t count, uint8_t* blocked) {
    RTCIntersectContext context;
    rtcInitIntersectContext(&context);
    alignas(64) typename Packet<N>::Rays packet;
    alignas(64) int valid[N];
    for (size_t begin = 0; begin < count; begin += N) {
        for (int j = 0; j < N; ++j) {
            const bool live = begin + size_t(j) < count;
            const Ray& r = rays[live ? begin + size_t(j) : begin];
            valid[j] = live && ray_valid(r.origin, r.direction, r.tfar) ? -1 : 0;
            packet.org_x[j] = r.origin.x;
            packet.org_y[j] = r.origin.y;
            packet.org_z[j] = r.origin.z;
            packet.dir_x[j] = r.direction.x;
            packet.dir_y[j] = r.direction.y;
            packet.dir_z[j] = r.direction.z;
            packet.tnear[j] = 0.0f;
            packet.tfar[j] = r.tfar;
            packet.time[j] = 0.0f;
            packet.mask[j] = 0xFFFFFFFFu;
            packet.id[j] = 0;
            packet.flags[j] = 0;
        }
        Packet<N>::occluded(valid, scene, &context, &packet);
        for (int j = 0; j < N && begin + size_t(j) < count; ++j) {
            blocked[begin + size_t(j)] = valid[j] == 0 || packet.tfar[j] < 0.0f;
        }
    }
}

}  // namespace

void RayTracer::occluded(const Ray* rays, size_t count, uint8_t* blocked) const {
    occluded_packets<8>(impl_->scene, rays, count, blocked);
}

bool RayTracer::intersect(const glm::vec3& origin, const glm::vec3& direction, float tfar, Hit& hit) const {
    RTCIntersectContext context;
    rtcInitIntersectContext(&context);
    if (!ray_valid(origin, direction, tfar)) return false;
    RTCRayHit rayhit;
    rayhit.ray = make_ray(origin, direction, tfar);
    rayhit.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rayhit.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
    rtcIntersect1(impl_->scene, &context, &rayhit);
    if (rayhit.hit.geomID == RTC_INVALID_GEOMETRY_ID) return false;
    hit.mesh = int(rayhit.hit.geomID);
    hit.triangle = int64_t(rayhit.hit.primID);
    hit.u = rayhit.hit.u;
    hit.v = rayhit.hit.v;
    hit.t = rayhit.ray.tfar;
    return true;
}

int64_t RayTracer::occluded_batch(const float* rays, int64_t begin, int64_t end) const {
    RTCIntersectContext context;
    rtcInitIntersectContext(&context);
    int64_t count = 0;
    for (int64_t i = begin; i < end; ++i) {
        const float* r = rays + 7 * i;
        if (!ray_valid({r[0], r[1], r[2]}, {r[3], r[4], r[5]}, r[6])) continue;
        RTCRay ray = make_ray({r[0], r[1], r[2]}, {r[3], r[4], r[5]}, r[6]);
        rtcOccluded1(impl_->scene, &context, &ray);
        count += ray.tfar < 0.0f;
    }
    return count;
}

}  // namespace lmrefine
