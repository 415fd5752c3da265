#include "progress_binding.h"

namespace lmrefine::py_util {

PythonProgress::PythonProgress(py::object callback)
    : callback_(std::move(callback)),
      progress_([this](double fraction, const std::string& stage) { return report(fraction, stage); }) {
    if (!callback_.is_none() && !PyCallable_Check(callback_.ptr())) {
        throw py::type_error("progress must be a callable progress(fraction, stage) or None");
    }
}

bool PythonProgress::report(double fraction, const std::string& stage) {
    py::gil_scoped_acquire acquire;
    if (PyErr_CheckSignals() != 0) {
        error_.emplace();  // fetches the pending KeyboardInterrupt
        return false;
    }
    if (callback_.is_none()) return true;
    try {
        py::object answer = callback_(fraction, stage);
        // None (a plain print callback) goes on; any other false value cancels
        // (Python code reading an answer itself uses lmrefine.progressbar.cancels).
        if (answer.is_none()) return true;
        const int truth = PyObject_IsTrue(answer.ptr());
        if (truth < 0) throw py::error_already_set();
        return truth != 0;
    } catch (py::error_already_set& e) {
        error_.emplace(std::move(e));
        return false;
    }
}

void PythonProgress::rethrow_python_error() {
    if (error_) {
        py::error_already_set e = std::move(*error_);
        error_.reset();
        throw e;
    }
}

}  // namespace lmrefine::py_util
