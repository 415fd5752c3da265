#include "numpy_util.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "lmrefine/core/error.h"
#include "lmrefine/core/memory.h"

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

std::string type_name(const py::handle& object) {
    return py::str(py::type::of(object).attr("__name__")).cast<std::string>();
}

}  // namespace

namespace {

// A view into a buffer at an odd offset is C-contiguous but not aligned: the
// kernels read it as float or int, which needs the element's alignment.
bool aligned(const py::array& array) {
    return (array.flags() & py::detail::npy_api::NPY_ARRAY_ALIGNED_) != 0;
}

}  // namespace

py::array contiguous_array(const py::handle& object, const char* name, const py::dtype& dtype) {
    if (py::isinstance<py::array>(object)) {
        auto array = py::reinterpret_borrow<py::array>(object);
        const bool as_is = array.dtype().equal(dtype) && (array.flags() & py::array::c_style) && aligned(array);
        if (as_is) return array;
        require_memory(std::string("a contiguous ") + py::str(py::handle(dtype)).cast<std::string>() + " copy of " + name +
                           " " + shape_string(array),
                       saturating_product({uint64_t(array.size()), uint64_t(dtype.itemsize())}),
                       std::string("pass a smaller ") + name);
    }
    try {
        const py::module_ numpy = py::module_::import("numpy");
        py::array array = numpy.attr("ascontiguousarray")(object, dtype);
        // ascontiguousarray hands back an unaligned contiguous array as it is; a copy is aligned.
        if (!aligned(array)) array = numpy.attr("array")(array, py::arg("copy") = true);
        return array;
    } catch (py::error_already_set& e) {
        const std::string message = std::string(name) + " cannot be converted to a " +
                                    py::str(py::handle(dtype)).cast<std::string>() + " array: " + e.what();
        if (e.matches(PyExc_MemoryError)) throw ResourceError(message);
        throw py::value_error(message);
    }
}

int64_t int_param(const py::handle& value, const char* name, int64_t min, int64_t max) {
    if (py::isinstance<py::bool_>(value) || !PyIndex_Check(value.ptr())) {
        throw py::type_error(std::string(name) + " must be an int, got " + type_name(value));
    }
    py::object index = py::reinterpret_steal<py::object>(PyNumber_Index(value.ptr()));
    if (!index) throw py::error_already_set();
    int overflow = 0;
    const long long n = PyLong_AsLongLongAndOverflow(index.ptr(), &overflow);
    if (overflow < 0 || (overflow == 0 && n < min)) {
        throw py::value_error(std::string(name) + (min == 1 ? " must be positive" : " must be >= " + std::to_string(min)) +
                              ", got " + py::str(index).cast<std::string>());
    }
    if (overflow > 0 || n > max) {
        throw py::value_error(std::string(name) + " must be at most " + std::to_string(max) + ", got " +
                              py::str(index).cast<std::string>());
    }
    return n;
}

double real_param(const py::handle& value, const char* name) {
    if (py::isinstance<py::bool_>(value) || py::isinstance<py::str>(value) || !PyNumber_Check(value.ptr()) ||
        (py::isinstance<py::array>(value) && py::reinterpret_borrow<py::array>(value).ndim() != 0)) {
        throw py::type_error(std::string(name) + " must be a number, got " + type_name(value));
    }
    const double x = PyFloat_AsDouble(value.ptr());
    if (x == -1.0 && PyErr_Occurred()) {
        PyErr_Clear();
        throw py::type_error(std::string(name) + " must be a real number, got " + type_name(value));
    }
    if (!std::isfinite(x)) throw py::value_error(std::string(name) + " must be finite, got " + std::to_string(x));
    return x;
}

std::string string_param(const py::handle& value, const char* name) {
    if (!py::isinstance<py::str>(value)) {
        throw py::type_error(std::string(name) + " must be a str, got " + type_name(value));
    }
    Py_ssize_t size = 0;
    const char* utf8 = PyUnicode_AsUTF8AndSize(value.ptr(), &size);
    if (utf8 == nullptr) {  // lone surrogates have no UTF-8
        PyErr_Clear();
        throw py::value_error(std::string(name) + " is not valid text (it holds a lone surrogate), got " +
                              py::repr(value).cast<std::string>());
    }
    return std::string(utf8, size_t(size));
}

bool bool_param(const py::handle& value, const char* name) {
    const bool is_numpy_bool = py::isinstance(value, py::module_::import("numpy").attr("bool_"));
    if (!py::isinstance<py::bool_>(value) && !is_numpy_bool && !PyLong_Check(value.ptr())) {
        throw py::type_error(std::string(name) + " must be a bool, got " + type_name(value));
    }
    const int truth = PyObject_IsTrue(value.ptr());
    if (truth < 0) throw py::error_already_set();
    return truth != 0;
}

std::string path_param(const py::handle& value, const char* name) {
    py::object path;
    try {
        path = py::module_::import("os").attr("fspath")(value);
    } catch (py::error_already_set&) {
        throw py::type_error(std::string(name) + " must be a str or os.PathLike, got " + type_name(value));
    }
    if (!py::isinstance<py::str>(path)) {
        throw py::type_error(std::string(name) + " must be a str path, got " + type_name(path));
    }
    // The file system's bytes, as Python's own open() makes them (undecodable
    // bytes come back from their surrogate escapes).
    const std::string text = py::module_::import("os").attr("fsencode")(path).cast<std::string>();
    if (text.find('\0') != std::string::npos) {
        throw py::value_error(std::string(name) + " contains a NUL character; a file name cannot hold one");
    }
    if (text.empty()) throw py::value_error(std::string(name) + " is empty; pass a file name");
    return text;
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
    return contiguous<float>(array, name);
}

FloatArray require_points(const py::handle& object, const char* name, int columns, bool allow_empty) {
    py::array array = as_array(object, name);
    const char kind = array.dtype().kind();
    if (kind != 'f' && kind != 'i' && kind != 'u') {
        throw py::value_error(std::string(name) + " must hold real numbers, got dtype " + dtype_name(array));
    }
    require_columns(array, name, columns, allow_empty);
    return contiguous<float>(array, name);
}

IndexArray require_indices(const py::handle& object, const char* name, int columns, bool allow_empty) {
    py::array array = as_array(object, name);
    const char kind = array.dtype().kind();
    if (kind != 'i' && kind != 'u') {
        throw py::value_error(std::string(name) + " must hold integers, got dtype " + dtype_name(array));
    }
    require_columns(array, name, columns, allow_empty);
    if (array.dtype().equal(py::dtype::of<int32_t>())) return contiguous<int32_t>(array, name);
    // Range-check before narrowing so a huge index is reported, not wrapped.
    auto wide = wide_integers(array, name);
    const int64_t* p = wide.data();
    for (py::ssize_t i = 0; i < wide.size(); ++i) {
        if (p[i] < 0 || p[i] > std::numeric_limits<int32_t>::max()) {
            throw py::value_error(std::string(name) + "[" + std::to_string(i / columns) + "] holds index " +
                                  element_text(array, i) + ", outside the int32 range of valid indices");
        }
    }
    return contiguous<int32_t>(array, name);
}

py::array_t<int64_t, py::array::c_style> wide_integers(const py::array& array, const char* name) {
    auto wide = contiguous<int64_t>(array, name);
    if (array.dtype().kind() == 'u' && array.dtype().itemsize() == 8) {  // a copy: the dtype differs
        int64_t* p = wide.mutable_data();
        for (py::ssize_t i = 0; i < wide.size(); ++i) {
            if (p[i] < 0) p[i] = std::numeric_limits<int64_t>::max();
        }
    }
    return wide;
}

std::string element_text(const py::array& array, py::ssize_t flat_index) {
    return py::str(array.attr("flat")[py::int_(flat_index)]).cast<std::string>();
}

std::pair<std::vector<int32_t>, int32_t> require_chart_ids(const py::handle& charts, int64_t triangle_count) {
    py::array array = py::array::ensure(charts);
    if (!array || (array.dtype().kind() != 'i' && array.dtype().kind() != 'u')) {
        throw py::value_error("charts must be an integer array of chart ids, one per triangle");
    }
    if (array.ndim() != 1 || array.shape(0) != triangle_count) {
        throw py::value_error("charts must have shape (" + std::to_string(triangle_count) +
                              ",): one chart id per triangle, got " + shape_string(array));
    }
    const auto wide = wide_integers(array, "charts");
    std::vector<int32_t> ids(static_cast<size_t>(triangle_count));
    int32_t count = 0;
    for (py::ssize_t t = 0; t < wide.size(); ++t) {
        const int64_t c = wide.data()[t];
        if (c < 0 || c >= triangle_count) {
            throw py::value_error("charts[" + std::to_string(t) + "] is " + element_text(array, t) +
                                  "; chart ids must be in [0, " + std::to_string(triangle_count) +
                                  "), one below the triangle count: number the charts 0..C-1 (find_charts does)");
        }
        ids[size_t(t)] = int32_t(c);
        count = std::max(count, int32_t(c) + 1);
    }
    return {std::move(ids), count};
}

std::pair<int, int> parse_resolution(const py::handle& resolution, const char* what, uint64_t bytes_per_texel) {
    constexpr int64_t kMax = int64_t(1) << 24;
    int64_t height = 0, width = 0;
    if (PyIndex_Check(resolution.ptr()) && !py::isinstance<py::bool_>(resolution)) {
        height = width = int_param(resolution, "resolution", 1, kMax);
    } else if (py::isinstance<py::sequence>(resolution) && !py::isinstance<py::str>(resolution) &&
               !py::isinstance<py::bytes>(resolution)) {
        auto sequence = py::reinterpret_borrow<py::sequence>(resolution);
        if (py::len(sequence) != 2) {
            throw py::value_error("resolution must be an int or (height, width), got " +
                                  std::to_string(py::len(sequence)) + " numbers");
        }
        height = int_param(sequence[0], "resolution", 1, kMax);
        width = int_param(sequence[1], "resolution", 1, kMax);
    } else {
        throw py::type_error("resolution must be an int or (height, width), got " + type_name(resolution));
    }
    if (bytes_per_texel > 0) require_memory(std::string(what) + " at " + std::to_string(height) + "x" + std::to_string(width),
                   saturating_product({uint64_t(height), uint64_t(width), bytes_per_texel}),
                   "lower the resolution");
    return {int(height), int(width)};
}

py::array_t<bool> layout_mask(
    const py::handle& uvs_in, const py::handle& triangles_in, const py::handle& resolution,
    const std::function<std::vector<uint8_t>(const UvLayout&, int, int)>& compute) {
    auto uvs = require_points(uvs_in, "uvs", 2);
    auto triangles = require_indices(triangles_in, "triangles", 3, /*allow_empty=*/true);
    const auto [height, width] = parse_resolution(resolution, "a coverage mask");
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
