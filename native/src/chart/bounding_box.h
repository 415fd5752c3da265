// The turn that gives a flattened chart its smallest bounding box: the
// packer turns charts only by quarter turns, so a square chart unwrapped
// along its diagonal would take twice its area in the atlas.
#pragma once

#include <vector>

#include <glm/vec2.hpp>

namespace lmrefine::chart {

// Unit direction (cos, sin) of the angle to turn `points` by (about the
// origin) so their axis-aligned box is smallest. A minimal-area rectangle
// has a side along an edge of the convex hull, so only those are tried.
glm::dvec2 smallest_box_turn(const std::vector<glm::dvec2>& points);

}  // namespace lmrefine::chart
