// Nearest points in the plane (pixel space), for the baker's border texels
// and the dilation's nearest chart.
#pragma once

#include <algorithm>
#include <limits>

#include <glm/geometric.hpp>
#include <glm/vec2.hpp>

namespace lmrefine {

// The point of segment ab nearest to p.
inline glm::dvec2 nearest_on_segment(const glm::dvec2& p, const glm::dvec2& a, const glm::dvec2& b) {
    const glm::dvec2 ab = b - a;
    const double length2 = glm::dot(ab, ab);
    const double t = length2 > 0.0 ? std::clamp(glm::dot(p - a, ab) / length2, 0.0, 1.0) : 0.0;
    return a + ab * t;
}

// Squared distance from p to the triangle with corners c (0 inside it or on its border).
inline double squared_distance_to_triangle(const glm::dvec2& p, const glm::dvec2 (&c)[3]) {
    double side[3];
    for (int i = 0; i < 3; ++i) {
        const glm::dvec2 a = c[i], b = c[(i + 1) % 3];
        side[i] = (b.x - a.x) * (p.y - a.y) - (b.y - a.y) * (p.x - a.x);
    }
    if ((side[0] >= 0 && side[1] >= 0 && side[2] >= 0) || (side[0] <= 0 && side[1] <= 0 && side[2] <= 0)) return 0.0;
    double best = std::numeric_limits<double>::infinity();
    for (int i = 0; i < 3; ++i) {
        const glm::dvec2 q = nearest_on_segment(p, c[i], c[(i + 1) % 3]);
        best = std::min(best, glm::dot(q - p, q - p));
    }
    return best;
}

}  // namespace lmrefine
