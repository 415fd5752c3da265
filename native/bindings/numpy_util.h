// Checks numpy arrays where they enter and hands results back without copies.
#pragma once

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <functional>
#include <initializer_list>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "lmrefine/layout/coverage.h"

namespace lmrefine::py_util {

namespace py = pybind11;

using FloatArray = py::array_t<float, py::array::c_style>;
using IndexArray = py::array_t<int32_t, py::array::c_style>;

std::string shape_string(const py::array& array);
std::string dtype_name(const py::array& array);

// Image-sized arrays: float32 required, so no hidden copy of a large image is
// made (a non-contiguous float32 view is made contiguous, which copies).
// ndim must be one of `ndims`; no dimension may be zero.
FloatArray require_float32(const py::handle& object, const char* name,
                           std::initializer_list<int> ndims);

// Geometry arrays (UVs, positions, normals): any real dtype, converted to
// float32 (they are small next to a lightmap). Shape (N, columns).
FloatArray require_points(const py::handle& object, const char* name, int columns,
                          bool allow_empty = false);

// Index arrays: any integer dtype, converted to int32 with a range check.
// Shape (N, columns).
IndexArray require_indices(const py::handle& object, const char* name, int columns,
                           bool allow_empty = false);

// The one input-validation layer of the boundary: every public function
// reads its arguments through these, so a wrong type is a TypeError and a
// bad value a ValueError naming the argument (never pybind11's "Unable to
// cast"), and a copy is checked against memory before it is made.

// `object` as a C-contiguous array of T: no copy when it already is one;
// otherwise a copy, checked against memory first (MemoryError naming `name`)
// and made by numpy, whose failure becomes a ValueError/MemoryError naming
// `name` (pybind11's ensure() would return a null array).
py::array contiguous_array(const py::handle& object, const char* name, const py::dtype& dtype);
template <class T>
py::array_t<T, py::array::c_style> contiguous(const py::handle& object, const char* name) {
    return py::reinterpret_borrow<py::array_t<T, py::array::c_style>>(
        contiguous_array(object, name, py::dtype::of<T>()));
}

// The integers of `array` (any integer dtype) as int64 in C order, for a
// range check. A uint64 value past int64's range would wrap to a negative
// (2**64 - 1 read as -1); it saturates to int64's largest instead, past every
// caller's range: print a refused value with element_text.
py::array_t<int64_t, py::array::c_style> wide_integers(const py::array& array, const char* name);
// Element `flat_index` (C order) of `array`, as numpy prints it.
std::string element_text(const py::array& array, py::ssize_t flat_index);

// Chart ids, one per triangle (an integer array of shape (triangle_count,)),
// each in [0, triangle_count): below the triangle count, so every per-chart
// array is bounded by the input's size. Returns the ids and the chart count
// (the largest id + 1).
std::pair<std::vector<int32_t>, int32_t> require_chart_ids(const py::handle& charts, int64_t triangle_count);

// A Python int (or numpy integer; not bool) in [min, max].
int64_t int_param(const py::handle& value, const char* name, int64_t min, int64_t max);
// A real number (int, float or numpy scalar; not bool, not str), finite.
double real_param(const py::handle& value, const char* name);
// A str.
std::string string_param(const py::handle& value, const char* name);
// A flag: bool, numpy.bool_ or an int (its truth).
bool bool_param(const py::handle& value, const char* name);
// A file path: str or os.PathLike; NUL characters are rejected (the C
// library would cut the name at the first one).
std::string path_param(const py::handle& value, const char* name);

// A lightmap resolution: an int (square) or (height, width), each in
// [1, 2^24]; the texels times `bytes_per_texel` must fit in memory
// (MemoryError naming `what` otherwise; 0 skips the check, for a caller
// with its own estimate). Returns (height, width).
std::pair<int, int> parse_resolution(const py::handle& resolution, const char* what = "a lightmap",
                                     uint64_t bytes_per_texel = 16);

// A per-texel byte mask computed from a UV layout (uvs (N, 2), triangles
// (T, 3), resolution) with the GIL released, returned as (H, W) bool without
// a copy (bool and uint8 share a layout).
py::array_t<bool> layout_mask(
    const py::handle& uvs, const py::handle& triangles, const py::handle& resolution,
    const std::function<std::vector<uint8_t>(const UvLayout& layout, int width, int height)>& compute);

// Moves a vector into a numpy array of the given shape without copying; the
// array owns the storage through a capsule.
template <class T, class A>
py::array_t<T> to_numpy(std::vector<T, A>&& data, std::vector<py::ssize_t> shape) {
    auto owner = std::make_unique<std::vector<T, A>>(std::move(data));
    T* pointer = owner->data();
    py::capsule capsule(owner.get(), [](void* p) { delete static_cast<std::vector<T, A>*>(p); });
    owner.release();
    return py::array_t<T>(std::move(shape), pointer, capsule);
}

}  // namespace lmrefine::py_util
