#include "numpy_util.h"

#include <algorithm>
#include <limits>

namespace lmrefine::py_util {

std::string shape_string(const py::array& array) {
    std::string s = "(";
    for (py::ssize_t i = 0; i < array.ndim(); ++i) {
        if (i) s += ", ";
        s += std::to_string(array.shape(i));
    }
    if (array.ndim() == 1) s += ",";
    return s + ")";
}

std::string dtype_name(const py::array& array) {
    return py::str(array.dtype()).cast<std::string>();
}

namespace {

py::array as_array(const py::handle& object, const char* name) {
    if (object.is_none()) throw py::value_error(std::string(name) + " is None; pass a numpy array");
    if (!py::isinstance<py::array>(object)) {
        throw py::value_error(std::string(name) + " must be a numpy array, got " +
                              py::str(py::type::of(object).attr("__name__")).cast<std::string>());
    }
    return py::reinterpret_borrow<py::array>(object);
}

void require_ndim(const py::array& array, const char* name, std::initializer_list<int> ndims) {
    if (std::find(ndims.begin(), ndims.end(), int(array.ndim())) == ndims.end()) {
        std::string allowed;
        for (int n : ndims) allowed += (allowed.empty() ? "" : " or ") + std::to_string(n);
        throw py::value_error(std::string(name) + " must have " + allowed + " dimensions, got shape " +
                              shape_string(array));
    }
}

void require_columns(const py::array& array, const char* name, int columns, bool allow_empty) {
    if (array.ndim() != 2 || array.shape(1) != columns) {
        throw py::value_error(std::string(name) + " must have shape (N, " + std::to_string(columns) +
                              "), got " + shape_string(array));
    }
    if (!allow_empty && array.shape(0) == 0) throw py::value_error(std::string(name) + " is empty");
}

}  // namespace

FloatArray require_float32(const py::handle& object, const char* name, std::initializer_list<int> ndims) {
    py::array array = as_array(object, name);
    // Equal, not the same object: an unpickled array (multiprocessing) has
    // its own float32 dtype object. Byte-swapped float32 is not equal.
    if (!array.dtype().equal(py::dtype::of<float>())) {
        throw py::value_error(std::string(name) + " must be float32, got " + dtype_name(array) +
                              "; convert it with " + name + ".astype(numpy.float32)");
    }
    require_ndim(array, name, ndims);
    for (py::ssize_t i = 0; i < array.ndim(); ++i) {
        if (array.shape(i) == 0) throw py::value_error(std::string(name) + " is empty: shape " + shape_string(array));
    }
    return FloatArray::ensure(array);
}

FloatArray require_points(const py::handle& object, const char* name, int columns, bool allow_empty) {
    py::array array = as_array(object, name);
    const char kind = array.dtype().kind();
    if (kind != 'f' && kind != 'i' && kind != 'u') {
        throw py::value_error(std::string(name) + " must hold real numbers, got dtype " + dtype_name(array));
    }
    require_columns(array, name, columns, allow_empty);
    return py::array_t<float, py::array::c_style | py::array::forcecast>::ensure(array);
}

IndexArray require_indices(const py::handle& object, const char* name, int columns, bool allow_empty) {
    py::array array = as_array(object, name);
    const char kind = array.dtype().kind();
    if (kind != 'i' && kind != 'u') {
        throw py::value_error(std::string(name) + " must hold integers, got dtype " + dtype_name(array));
    }
    require_columns(array, name, columns, allow_empty);
    if (array.dtype().equal(py::dtype::of<int32_t>())) return IndexArray::ensure(array);
    // Range-check before narrowing so a huge index is reported, not wrapped.
    py::array_t<int64_t, py::array::c_style | py::array::forcecast> wide(array);
    const int64_t* p = wide.data();
    for (py::ssize_t i = 0; i < wide.size(); ++i) {
        if (p[i] < 0 || p[i] > std::numeric_limits<int32_t>::max()) {
            throw py::value_error(std::string(name) + "[" + std::to_string(i / columns) + "] holds index " +
                                  std::to_string(p[i]) + ", outside the int32 range of valid indices");
        }
    }
    return py::array_t<int32_t, py::array::c_style | py::array::forcecast>::ensure(array);
}

std::pair<int, int> parse_resolution(const py::handle& resolution) {
    int height = 0, width = 0;
    if (py::isinstance<py::int_>(resolution)) {
        height = width = resolution.cast<int>();
    } else if (py::isinstance<py::sequence>(resolution) && py::len(resolution) == 2) {
        auto sequence = py::reinterpret_borrow<py::sequence>(resolution);
        height = sequence[0].cast<int>();
        width = sequence[1].cast<int>();
    } else {
        throw py::value_error("resolution must be an int or (height, width)");
    }
    if (height <= 0 || width <= 0) {
        throw py::value_error("resolution must be positive, got " + std::to_string(height) + "x" +
                              std::to_string(width));
    }
    return {height, width};
}

py::array_t<bool> layout_mask(
    const py::handle& uvs_in, const py::handle& triangles_in, const py::handle& resolution,
    const std::function<std::vector<uint8_t>(const UvLayout&, int, int)>& compute) {
    auto uvs = require_points(uvs_in, "uvs", 2);
    auto triangles = require_indices(triangles_in, "triangles", 3, /*allow_empty=*/true);
    const auto [height, width] = parse_resolution(resolution);
    UvLayout layout{uvs.data(), uvs.shape(0), triangles.data(), triangles.shape(0)};
    std::vector<uint8_t> mask;
    {
        py::gil_scoped_release release;
        mask = compute(layout, width, height);
    }
    auto bytes = to_numpy(std::move(mask), {height, width});
    return bytes.attr("view")(py::dtype::of<bool>()).cast<py::array_t<bool>>();
}

}  // namespace lmrefine::py_util
