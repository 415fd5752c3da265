// Fitting a layout to target triangle shapes (the triangle stretch,
// docs/refiner.md): each triangle's edges should become its target map D_t
// times its edges now. The least-squares compromise over every edge of every
// triangle (an edge's residual relative to its length, weighted by its
// triangle's area), with a faint pull to the current positions so that each
// connected piece keeps its place and the normal equations stay definite.
// The u and v coordinates decouple: one sparse Cholesky factorisation (Eigen's
// SimplicialLDLT) of the weighted graph Laplacian, two solves.
#pragma once

#include <cstdint>
#include <vector>

#include <glm/vec2.hpp>

namespace lmrefine {

struct ShapeFitInput {
    const double* uvs = nullptr;         // (vertices, 2)
    int64_t vertices = 0;
    const int32_t* triangles = nullptr;  // (triangle_count, 3), indices in [0, vertices)
    int64_t triangle_count = 0;
    const double* targets = nullptr;     // (triangle_count, 2, 2) row-major: D_t
};

// The fitted positions, one per vertex. A vertex no triangle uses stays where
// it is; a triangle without area adds nothing. Throws InvalidArgument on an
// index out of range or a non-finite input, Error if the system cannot be
// solved.
std::vector<glm::dvec2> fit_shapes(const ShapeFitInput& input);

}  // namespace lmrefine
