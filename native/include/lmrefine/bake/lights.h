// Lights in Blender's own terms and units, and how the baker samples them.
//
// A light's "value" at a surface point is what Cycles' DIFFUSE bake with the
// colour pass off stores: the incident radiance integrated against cos/pi,
// i.e. irradiance / pi. Calibrated against Blender 3.4's Cycles
// (docs/baker.md):
//   point, spot  radiant intensity P / (4 pi) W/sr (a sphere of radius
//                shadow_soft_size seen as a disk of radiance P / (4 pi^2 r^2))
//   spot         the point light times Cycles' spot attenuation: the cosine to
//                the spot axis, zero outside spot_size, smoothstep over spot_blend
//   sun          irradiance `energy` W/m^2 at normal incidence, spread over a
//                cone of angular diameter `angle`
//   area         one-sided Lambertian emitter of radiance P / (4 A)
//
// Orientation (Blender's): a light emits along its local -Z (`direction`); an
// area light's `size` runs along its local +X (`axis_x`), `size_y` along
// local +Y = cross(local Z, local X). Spin about the axis only matters for
// area lights: Cycles 3.4's point, spot and sun lights are round.
#pragma once

#include <glm/mat4x4.hpp>
#include <glm/vec2.hpp>
#include <glm/vec3.hpp>

namespace lmrefine {

enum class LightKind { Point, Spot, Sun, Area };
enum class AreaShape { Square, Rectangle, Disk, Ellipse };

struct Light {
    LightKind kind = LightKind::Point;
    glm::vec3 color{1.0f};
    float energy = 10.0f;            // W (point, spot, area) or W/m^2 (sun)
    glm::vec3 position{0.0f};        // point, spot, area
    glm::vec3 direction{0, 0, -1};   // where the light points (spot, sun, area); unit length
    // The light's local +X in world space (an area light's `size` runs along
    // it). Zero: the orientation Blender gives a light aimed along `direction`
    // by Vector.to_track_quat('-Z', 'Y') (local Y leans to world +Z). After
    // validate_light: unit length and perpendicular to `direction`.
    glm::vec3 axis_x{0.0f};
    float shadow_soft_size = 0.25f;  // radius of a point or spot light (Blender's default)
    float angle = 0.00918043f;       // sun's angular diameter, radians (Blender's default, 0.526 deg)
    float spot_size = 0.785398f;     // spot cone's full angle, radians
    float spot_blend = 0.15f;        // fraction of the cone that fades out
    AreaShape shape = AreaShape::Square;
    float size = 0.25f;              // area light X extent (diameter for disk and ellipse)
    float size_y = 0.25f;            // area light Y extent (rectangle, ellipse)
};

// Throws InvalidArgument naming the bad parameter (negative energy, NaN, an
// axis_x parallel to direction, ...). Normalizes `direction`, and makes
// `axis_x` a unit vector perpendicular to it (Gram-Schmidt), or derives it.
void validate_light(Light& light);

// Places the light as Cycles (Blender 3.4) places a light object with world
// matrix `matrix` (Blender's matrix_world; column c is local axis c, column 3
// the position): position = column 3, direction = -column 2, axis_x =
// column 0. An area light's extents are scaled by the lengths of columns 0
// and 1 (a square or disk with unequal scales becomes a rectangle or
// ellipse); the scale of point, spot and sun lights is ignored, as Cycles 3.4
// ignores it (docs/baker.md, "Orientation: spin and scale"). Call
// after setting shape, size and size_y; throws InvalidArgument for a
// non-finite or non-affine matrix, or a zero-length axis.
void place_light(Light& light, const glm::mat4& matrix);

// One sample of a light as seen from `point`: the unit direction towards the
// light, the distance to check for shadows (infinite for the sun), and the
// value it adds when unoccluded, to be multiplied by max(0, dot(normal, direction)).
struct LightSample {
    glm::vec3 direction{0.0f};
    float distance = 0.0f;
    glm::vec3 value{0.0f};
};

// `u` in [0, 1)^2 picks the point on the light. Returns false when the light
// cannot reach `point` (behind an area light, outside a spot cone).
bool sample_light(const Light& light, const glm::vec3& point, const glm::vec2& u, LightSample& sample);

}  // namespace lmrefine
