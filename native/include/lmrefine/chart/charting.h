// Surface charts: a triangle mesh cut into charts of neighbouring faces whose
// normals stay within an angle of the chart's first face, ready to be
// unwrapped one by one (conformal_map.h) and packed (pack/packer.h). Faces
// are neighbours when they share an edge in 3D: positions are welded first,
// since a lightmap UV split (Lightmap Pack cuts every face) may have left
// coincident copies of one vertex. Details: docs/refiner.md, "Re-charting".
#pragma once

#include <cstdint>
#include <vector>

#include <glm/vec3.hpp>

namespace lmrefine {

// A triangle mesh as it crosses the boundary. Views only.
struct SurfaceMesh {
    const float* positions = nullptr;    // (vertex_count, 3)
    int64_t vertex_count = 0;
    const int32_t* triangles = nullptr;  // (triangle_count, 3) indices into positions
    int64_t triangle_count = 0;
    // (triangle_count * 3, 3) shading normal per corner, or null. Where the
    // two faces of an edge have the same shading normals at both its ends
    // the mesh is smooth-shaded there: the light has no step to cut at.
    const float* corner_normals = nullptr;
    // (triangle_count) polygon id per triangle, or null: triangles with one
    // id are one polygon of the source mesh (a quad's or an n-gon's
    // triangles, which share their corners' UVs) and always join one chart.
    const int32_t* polygons = nullptr;
};

// Throws InvalidArgument naming the first index out of range or
// non-finite position a triangle uses (loose vertices are not read).
void validate_surface(const SurfaceMesh& mesh);

// Per vertex, the smallest index of the used vertices it is welded to
// (positions closer than `tolerance`, chained); itself when none or unused.
std::vector<int32_t> weld_positions(const SurfaceMesh& mesh, double tolerance);

// Per-face geometry and its edge neighbours on the welded mesh.
struct SurfaceFaces {
    std::vector<glm::dvec3> normal;    // unit, from the winding; 0 for a degenerate face
    std::vector<double> area;          // world-space area
    std::vector<uint8_t> degenerate;   // zero area, a sliver or two corners welded together
    // Per face and edge k (corner k to corner k + 1): the face across it, or
    // -1 when none, the edge is shared by more than two faces, the two
    // faces wind it the same way (a flipped neighbour would fold), or
    // either face is degenerate.
    std::vector<int64_t> neighbour;    // (triangle_count * 3)
    // Per face and edge: 1 when it has a neighbour and the mesh is
    // smooth-shaded across it (SurfaceMesh::corner_normals); all 0 without
    // shading normals (every edge hard).
    std::vector<uint8_t> smooth;       // (triangle_count * 3)
    // Per face, the next face of its polygon (SurfaceMesh::polygons), round
    // a cycle back to it, and the polygon's smallest face; itself for a face
    // alone in its polygon.
    std::vector<int64_t> polygon_next;  // (triangle_count)
    std::vector<int64_t> polygon_root;  // (triangle_count)
};

SurfaceFaces surface_faces(const SurfaceMesh& mesh, const std::vector<int32_t>& welded);

// Grows charts over `faces` (non-degenerate face ids): the largest face not
// yet in a chart (faces within about 1% of one size: the first index) seeds one, which takes every face reachable through edge
// neighbours in `faces` whose normal is within `angle_radians` of the
// seed's, or within `smooth_angle_radians` when the edge crossed is smooth
// (SurfaceFaces::smooth); a face that joins brings the other faces of its
// polygon in `faces` with it, whatever their normals. Every chart is
// edge-connected, and for angles below 90 degrees no face of a chart turns
// its back to the seed's plane unless a polygon's other face does.
// Deterministic.
std::vector<std::vector<int64_t>> grow_charts(const SurfaceFaces& faces, const std::vector<int64_t>& face_ids,
                                              double angle_radians, double smooth_angle_radians);

// A chart (two or more face ids) cut in two halves at the median of its
// face centroids along their widest axis (a polygon's faces at the
// centroid of their polygon, so that no polygon is cut, unless the chart is
// one polygon), each half split into its edge-connected parts: for a chart whose faces all lie within a small
// angle and that still folds (a folded or self-intersecting input), so the
// fold ends up in a small chart instead of the whole chart in single faces.
std::vector<std::vector<int64_t>> bisect_chart(const SurfaceMesh& mesh, const SurfaceFaces& faces,
                                               const std::vector<int64_t>& chart);

}  // namespace lmrefine
