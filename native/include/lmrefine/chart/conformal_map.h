// Least-squares conformal maps (Levy et al. 2002): a chart of a triangle
// mesh flattened so every triangle keeps its angles as well as possible
// (the Cauchy-Riemann equations in each triangle's own plane, weighted by
// its area, solved in the least-squares sense with two vertices pinned).
// A planar chart comes out as an isometry up to scale. The sparse normal
// equations are solved with Eigen's SimplicialLDLT.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include <glm/vec2.hpp>
#include <glm/vec3.hpp>

namespace lmrefine {

struct ChartMesh {
    std::vector<glm::dvec3> positions;
    std::vector<std::array<int32_t, 3>> triangles;  // indices into positions; edge-connected, no degenerate face
};

// UVs per chart vertex, in units of the input's lengths up to a similarity.
// Empty if the system could not be solved (a chart that is not connected,
// or a numerically singular one); the caller splits such a chart.
std::vector<glm::dvec2> conformal_map(const ChartMesh& chart);

// Does a flattened chart fold or overlap itself: a triangle with a
// non-positive signed area (relative to the chart's size), or two
// triangles whose interiors intersect? (Sharing an edge or a corner is not
// an overlap.)
bool chart_overlaps_itself(const std::vector<glm::dvec2>& uvs, const std::vector<std::array<int32_t, 3>>& triangles);

}  // namespace lmrefine
