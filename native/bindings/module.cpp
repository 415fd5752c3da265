// lmrefine._native: the private extension module; the lmrefine package
// re-exports it. One bind_* function per concept, each in py_<concept>.cpp.
#include <pybind11/pybind11.h>

#include <algorithm>
#include <string>

#include "lmrefine/core/error.h"
#include "lmrefine/core/memory.h"
#include "lmrefine/core/parallel.h"

namespace py = pybind11;

namespace lmrefine::bindings {
void bind_image_io(py::module_& m);
void bind_coverage(py::module_& m);
void bind_texel_points(py::module_& m);
void bind_bilinear_lookup(py::module_& m);
void bind_chart(py::module_& m);
void bind_rechart(py::module_& m);
void bind_packer(py::module_& m);
void bind_automaton(py::module_& m);
void bind_warp(py::module_& m);
void bind_shape_fit(py::module_& m);
void bind_layout_check(py::module_& m);
void bind_wavelet(py::module_& m);
void bind_gradient_map(py::module_& m);
void bind_scene(py::module_& m);
void bind_baker(py::module_& m);
void bind_primary_rays(py::module_& m);
}  // namespace lmrefine::bindings

PYBIND11_MODULE(_native, m) {
    m.doc() = "lmrefine native core (C++17): wavelets, automaton, warp, baker, image I/O";
    m.attr("__version__") = LMREFINE_VERSION;

    static py::exception<lmrefine::Cancelled> cancelled(m, "CancelledError");
    cancelled.doc() = "A long call was cancelled (its progress callback returned False).";
    py::register_exception_translator([](std::exception_ptr p) {
        try {
            if (p) std::rethrow_exception(p);
        } catch (const lmrefine::Cancelled& e) {
            PyErr_SetString(cancelled.ptr(), "cancelled by the progress callback");
        } catch (const lmrefine::InvalidArgument& e) {
            PyErr_SetString(PyExc_ValueError, e.what());
        } catch (const lmrefine::IoError& e) {
            PyErr_SetString(PyExc_OSError, e.what());
        } catch (const lmrefine::ResourceError& e) {
            PyErr_SetString(PyExc_MemoryError, e.what());
        } catch (const lmrefine::Error& e) {
            PyErr_SetString(PyExc_RuntimeError, e.what());
        } catch (const py::cast_error& e) {
            // A safety net: arguments are read through py_util's checked
            // readers, which name the argument; a cast that slips past them
            // is still a wrong type, not a runtime failure.
            PyErr_SetString(PyExc_TypeError, e.what());
        }
    });

    lmrefine::bindings::bind_image_io(m);
    lmrefine::bindings::bind_coverage(m);
    lmrefine::bindings::bind_texel_points(m);
    lmrefine::bindings::bind_bilinear_lookup(m);
    lmrefine::bindings::bind_chart(m);
    lmrefine::bindings::bind_rechart(m);
    lmrefine::bindings::bind_packer(m);
    lmrefine::bindings::bind_automaton(m);
    lmrefine::bindings::bind_warp(m);
    lmrefine::bindings::bind_shape_fit(m);
    lmrefine::bindings::bind_layout_check(m);
    lmrefine::bindings::bind_wavelet(m);
    lmrefine::bindings::bind_gradient_map(m);
    lmrefine::bindings::bind_scene(m);
    lmrefine::bindings::bind_baker(m);
    lmrefine::bindings::bind_primary_rays(m);

    // The memory rule of the native core, for the allocations the Python
    // half makes itself (MemoryError before allocating, with the same words).
    m.def(
        "_require_memory",
        [](const std::string& what, double bytes, const std::string& advice) {
            lmrefine::require_memory(what, uint64_t(std::max(0.0, std::min(bytes, 1.8e19))), advice);
        },
        py::arg("what"), py::arg("bytes"), py::arg("advice"));

    // Registered by the package with os.register_at_fork(after_in_child=...).
    m.def("_serial_after_fork", &lmrefine::serial_after_fork,
          "Run every native loop serially from now on (called in a child made by fork()).");
}
