#include "lmrefine/bake/lights.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <glm/geometric.hpp>

#include "lmrefine/core/error.h"

namespace lmrefine {
namespace {

constexpr float kPi = 3.14159265358979f;

void require(bool ok, const char* message) {
    if (!ok) LMREFINE_THROW(InvalidArgument, message);
}

// An orthonormal frame (x, y) around unit n (Duff et al. 2017).
void frame(const glm::vec3& n, glm::vec3& x, glm::vec3& y) {
    const float sign = std::copysign(1.0f, n.z);
    const float a = -1.0f / (sign + n.z);
    const float b = n.x * n.y * a;
    x = {1.0f + sign * n.x * n.x * a, sign * b, -sign * n.x};
    y = {b, sign + n.y * n.y * a, -n.y};
}

// The local X axis Blender gives a light that points along `direction` with
// Vector.to_track_quat('-Z', 'Y'): local Y leans to world +Z, X = Y x Z. A
// light pointing straight down keeps world X and Y.
glm::vec3 default_axis_x(const glm::vec3& direction) {
    const glm::vec3 z = -direction;  // the light's local +Z
    const glm::vec3 up(0, 0, 1);
    glm::vec3 y_axis = up - glm::dot(up, z) * z;
    if (glm::length(y_axis) < 1e-6f) {
        y_axis = z.z > 0 ? glm::vec3(0, 1, 0) : glm::vec3(0, -1, 0);
    }
    return glm::cross(glm::normalize(y_axis), z);
}

// Uniform point in the unit disk, area preserving (Shirley-Chiu concentric map).
glm::vec2 concentric_disk(const glm::vec2& u) {
    const float a = 2.0f * u.x - 1.0f, b = 2.0f * u.y - 1.0f;
    if (a == 0.0f && b == 0.0f) return {0.0f, 0.0f};
    float r, phi;
    if (std::abs(a) > std::abs(b)) {
        r = a;
        phi = (kPi / 4) * (b / a);
    } else {
        r = b;
        phi = kPi / 2 - (kPi / 4) * (a / b);
    }
    return {r * std::cos(phi), r * std::sin(phi)};
}

float smoothstep(float edge0, float edge1, float x) {
    const float t = std::clamp((x - edge0) / (edge1 - edge0), 0.0f, 1.0f);
    return t * t * (3.0f - 2.0f * t);
}

// Cycles' spot_attenuation: cosine to the axis, cut at the cone, smoothed over the blend.
float spot_attenuation(const Light& light, const glm::vec3& from_light) {
    const float cos_half = std::cos(0.5f * light.spot_size);
    const float smooth = (1.0f - cos_half) * light.spot_blend;
    const float c = glm::dot(light.direction, from_light);
    if (c <= cos_half) return 0.0f;
    const float t = c - cos_half;
    return (t < smooth && smooth != 0.0f) ? c * smoothstep(0.0f, smooth, t) : c;
}

bool sample_point_light(const Light& light, const glm::vec3& point, const glm::vec2& u, LightSample& s) {
    glm::vec3 to_point = point - light.position;
    const float center_distance = glm::length(to_point);
    if (!(center_distance > 0.0f)) return false;
    const glm::vec3 axis = to_point / center_distance;
    // Cycles samples a sphere light as the disk facing the shading point.
    glm::vec3 source = light.position;
    if (light.shadow_soft_size > 0.0f) {
        glm::vec3 x, y;
        frame(axis, x, y);
        const glm::vec2 d = concentric_disk(u) * light.shadow_soft_size;
        source += x * d.x + y * d.y;
    }
    const glm::vec3 to_light = source - point;
    const float distance = glm::length(to_light);
    if (!(distance > 0.0f)) return false;
    s.direction = to_light / distance;
    s.distance = distance;
    const float cos_light = std::max(0.0f, glm::dot(axis, -s.direction));
    float factor = light.energy / (4.0f * kPi * kPi) * cos_light / (distance * distance);
    // Cycles attenuates along the sampled ray, so a spot's radius softens its cone's edge.
    if (light.kind == LightKind::Spot) factor *= spot_attenuation(light, -s.direction);
    s.value = light.color * factor;
    return factor > 0.0f;
}

bool sample_sun(const Light& light, const glm::vec2& u, LightSample& s) {
    const glm::vec3 towards = -light.direction;
    const float half = 0.5f * light.angle;
    if (half <= 0.0f) {
        s.direction = towards;
    } else {
        // Uniform in the cone's solid angle; radiance chosen so that the
        // irradiance at normal incidence is `energy`.
        const float cos_max = std::cos(half);
        const float cos_theta = 1.0f - u.x * (1.0f - cos_max);
        const float sin_theta = std::sqrt(std::max(0.0f, 1.0f - cos_theta * cos_theta));
        const float phi = 2.0f * kPi * u.y;
        glm::vec3 x, y;
        frame(towards, x, y);
        s.direction = glm::normalize(towards * cos_theta + (x * std::cos(phi) + y * std::sin(phi)) * sin_theta);
    }
    float factor = light.energy / kPi;
    if (half > 0.0f) {
        const float sin_max = std::sin(half);
        factor *= 2.0f * (1.0f - std::cos(half)) / (sin_max * sin_max);
    }
    s.distance = std::numeric_limits<float>::infinity();
    s.value = light.color * factor;
    return factor > 0.0f;
}

bool sample_area(const Light& light, const glm::vec3& point, const glm::vec2& u, LightSample& s) {
    // Local X and Y = Z x X (Z = -direction); validate_light made them orthonormal.
    const glm::vec3& x = light.axis_x;
    const glm::vec3 y = glm::cross(-light.direction, x);
    const bool square = light.shape == AreaShape::Square || light.shape == AreaShape::Disk;
    const float sx = light.size, sy = square ? light.size : light.size_y;
    glm::vec2 local;
    float area;
    if (light.shape == AreaShape::Disk || light.shape == AreaShape::Ellipse) {
        local = concentric_disk(u) * glm::vec2(0.5f * sx, 0.5f * sy);
        area = kPi * 0.25f * sx * sy;
    } else {
        local = (u - 0.5f) * glm::vec2(sx, sy);
        area = sx * sy;
    }
    if (!(area > 0.0f)) return false;
    const glm::vec3 source = light.position + x * local.x + y * local.y;
    const glm::vec3 to_light = source - point;
    const float distance = glm::length(to_light);
    if (!(distance > 0.0f)) return false;
    s.direction = to_light / distance;
    s.distance = distance;
    // One-sided: it emits along `direction` only.
    const float cos_light = glm::dot(light.direction, -s.direction);
    if (cos_light <= 0.0f) return false;
    // Radiance P / (4 A) (Cycles), times the area over the uniform pdf 1 / A.
    s.value = light.color * (light.energy / 4.0f * cos_light / (distance * distance) / kPi);
    return light.energy > 0.0f;
}

}  // namespace

void validate_light(Light& light) {
    require(std::isfinite(light.energy) && light.energy >= 0.0f, "light energy must be finite and >= 0");
    for (int k = 0; k < 3; ++k) {
        require(std::isfinite(light.color[k]) && light.color[k] >= 0.0f, "light color must be finite and >= 0");
        require(std::isfinite(light.position[k]), "light position must be finite");
        require(std::isfinite(light.direction[k]), "light direction must be finite");
        require(std::isfinite(light.axis_x[k]), "light axis_x must be finite");
    }
    const float length = glm::length(light.direction);
    require(length > 0.0f, "light direction must not be zero: it is where the light points");
    light.direction /= length;
    const float axis_length = glm::length(light.axis_x);
    if (axis_length == 0.0f) {
        light.axis_x = default_axis_x(light.direction);
    } else {
        // Gram-Schmidt: keep the spin about `direction`, drop any tilt out of the light's plane.
        const glm::vec3 x = light.axis_x / axis_length;
        const glm::vec3 across = x - glm::dot(x, light.direction) * light.direction;
        const float across_length = glm::length(across);
        require(across_length > 1e-4f,
                "light axis_x is parallel to direction; pass the light's local X axis (Blender: "
                "matrix_world column 0), which is perpendicular to where the light points");
        light.axis_x = across / across_length;
    }
    require(std::isfinite(light.shadow_soft_size) && light.shadow_soft_size >= 0.0f,
            "shadow_soft_size must be finite and >= 0");
    require(std::isfinite(light.angle) && light.angle >= 0.0f && light.angle < kPi,
            "sun angle must be in [0, pi) radians");
    require(std::isfinite(light.spot_size) && light.spot_size > 0.0f && light.spot_size <= kPi,
            "spot_size must be in (0, pi] radians");
    require(std::isfinite(light.spot_blend) && light.spot_blend >= 0.0f && light.spot_blend <= 1.0f,
            "spot_blend must be in [0, 1]");
    require(std::isfinite(light.size) && light.size > 0.0f, "area light size must be > 0");
    require(std::isfinite(light.size_y) && light.size_y > 0.0f, "area light size_y must be > 0");
}

void place_light(Light& light, const glm::mat4& matrix) {
    for (int c = 0; c < 4; ++c) {
        for (int r = 0; r < 4; ++r) require(std::isfinite(matrix[c][r]), "light matrix must be finite");
    }
    require(matrix[0][3] == 0.0f && matrix[1][3] == 0.0f && matrix[2][3] == 0.0f && matrix[3][3] == 1.0f,
            "light matrix must be an affine 4x4 world matrix with bottom row (0, 0, 0, 1), as Blender's "
            "matrix_world (rows of the matrix, translation in the last column)");
    const glm::vec3 x(matrix[0]), y(matrix[1]), z(matrix[2]);
    const float sx = glm::length(x), sy = glm::length(y), sz = glm::length(z);
    require(sx > 0.0f && sy > 0.0f && sz > 0.0f,
            "light matrix has a zero scale on one axis; give the light object a non-zero scale");
    light.position = glm::vec3(matrix[3]);
    light.direction = -z / sz;
    light.axis_x = x / sx;
    if (light.kind == LightKind::Area) {
        // Cycles' sync_light: axisu = column 0 * size, axisv = column 1 * size_y
        // (size for a square or disk), so the object's scale stretches the light.
        if (light.shape == AreaShape::Square || light.shape == AreaShape::Disk) {
            light.shape = light.shape == AreaShape::Square ? AreaShape::Rectangle : AreaShape::Ellipse;
            light.size_y = light.size;
        }
        light.size *= sx;
        light.size_y *= sy;
    }
}

bool sample_light(const Light& light, const glm::vec3& point, const glm::vec2& u, LightSample& sample) {
    switch (light.kind) {
        case LightKind::Point:
        case LightKind::Spot: return sample_point_light(light, point, u, sample);
        case LightKind::Sun: return sample_sun(light, u, sample);
        case LightKind::Area: return sample_area(light, point, u, sample);
    }
    return false;
}

}  // namespace lmrefine
