#include "weld.h"

#include <algorithm>
#include <cmath>

#include <glm/geometric.hpp>

#include "lmrefine/layout/chart.h"

namespace lmrefine::pack {
namespace {

// check_layout's orientation: +1 / -1, 0 when twice the area is below 1e-7
// of the longest edge squared (collinear to float precision).
int orientation(const glm::dvec2& a, const glm::dvec2& b, const glm::dvec2& c) {
    const glm::dvec2 e0 = b - a, e1 = c - a, e2 = c - b;
    const double cross = e0.x * e1.y - e0.y * e1.x;
    const double longest = std::max({glm::dot(e0, e0), glm::dot(e1, e1), glm::dot(e2, e2)});
    if (!(std::abs(cross) > 1e-7 * longest)) return 0;
    return cross > 0 ? 1 : -1;
}

}  // namespace

std::vector<glm::dvec2> snapped_uvs(const UvLayout& layout, const std::vector<int32_t>& chart_of_uv, double tolerance) {
    std::vector<glm::dvec2> own(size_t(layout.uv_count)), uvs(size_t(layout.uv_count));
    for (int64_t i = 0; i < layout.uv_count; ++i) own[size_t(i)] = {layout.uvs[2 * i], layout.uvs[2 * i + 1]};
    const std::vector<int64_t> weld = weld_corners(layout, tolerance);
    for (int64_t i = 0; i < layout.uv_count; ++i) {
        int64_t source = weld[size_t(i)];
        if (chart_of_uv[size_t(source)] != chart_of_uv[size_t(i)]) source = i;
        uvs[size_t(i)] = own[size_t(source)];
    }
    // A triangle the snap flips or flattens gets its own corners back; that
    // may change its neighbours (shared UV indices), so repeat until none
    // changes (each round restores at least one index: it ends).
    for (bool changed = true; changed;) {
        changed = false;
        for (int64_t t = 0; t < layout.triangle_count; ++t) {
            const int32_t* tri = layout.triangles + 3 * t;
            const int before = orientation(own[size_t(tri[0])], own[size_t(tri[1])], own[size_t(tri[2])]);
            const int after = orientation(uvs[size_t(tri[0])], uvs[size_t(tri[1])], uvs[size_t(tri[2])]);
            if (before == after || before == 0) continue;
            for (int k = 0; k < 3; ++k) {
                if (uvs[size_t(tri[k])] != own[size_t(tri[k])]) {
                    uvs[size_t(tri[k])] = own[size_t(tri[k])];
                    changed = true;
                }
            }
        }
    }
    return uvs;
}

}  // namespace lmrefine::pack
