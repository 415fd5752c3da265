// Bridges lmrefine::Progress to Python: a callable progress(fraction, stage)
// that cancels by returning a false value other than None (False, 0,
// numpy.False_) or by raising, plus Ctrl-C. Every report counts, the last
// one (fraction 1.0) included. Long calls run with the GIL
// released; the GIL is taken only to report.
#pragma once

#include <pybind11/pybind11.h>

#include <optional>
#include <type_traits>
#include <utility>

#include "lmrefine/core/error.h"
#include "lmrefine/core/progress.h"

namespace lmrefine::py_util {

namespace py = pybind11;

class PythonProgress {
public:
    // `callback` may be None; Ctrl-C is honoured either way.
    explicit PythonProgress(py::object callback);

    Progress& progress() { return progress_; }

    // Runs `work(progress)` with the GIL released. If it was cancelled
    // (even by the final report, after the work is done) because the
    // callback raised or Ctrl-C arrived, that Python exception is raised; if
    // the callback returned a false value, lmrefine.CancelledError.
    template <class Work>
    auto run(Work&& work) {
        try {
            py::gil_scoped_release release;
            if constexpr (std::is_void_v<decltype(work(progress_))>) {
                work(progress_);
                progress_.check();
            } else {
                auto result = work(progress_);
                progress_.check();
                return result;
            }
        } catch (const Cancelled&) {
            rethrow_python_error();
            throw;
        }
    }

private:
    bool report(double fraction, const std::string& stage);
    void rethrow_python_error();

    py::object callback_;
    std::optional<py::error_already_set> error_;
    Progress progress_;
};

}  // namespace lmrefine::py_util
