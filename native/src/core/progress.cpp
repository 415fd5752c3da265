#include "lmrefine/core/progress.h"

#include <algorithm>

#include "lmrefine/core/error.h"

namespace lmrefine {

Progress::Progress(Callback callback, double min_interval_seconds)
    : callback_(std::move(callback)),
      min_interval_(std::chrono::duration_cast<std::chrono::steady_clock::duration>(
          std::chrono::duration<double>(min_interval_seconds))) {}

void Progress::begin(const std::string& stage, uint64_t total) {
    stage_ = stage;
    total_ = total;
    done_.store(0);
    report(0.0);
}

void Progress::advance(uint64_t units) {
    done_.fetch_add(units, std::memory_order_relaxed);
    if (!callback_ || std::this_thread::get_id() != owner_) return;
    const auto now = std::chrono::steady_clock::now();
    if (now - last_report_ < min_interval_) return;
    report(fraction());
}

void Progress::finish() {
    done_.store(total_);
    report(1.0);
}

void Progress::check() const {
    if (cancelled()) throw Cancelled();
}

double Progress::fraction() const {
    if (total_ == 0) return 0.0;
    return std::min(1.0, double(done_.load(std::memory_order_relaxed)) / double(total_));
}

void Progress::report(double fraction) {
    if (!callback_ || std::this_thread::get_id() != owner_ || cancelled()) return;
    last_report_ = std::chrono::steady_clock::now();
    if (!callback_(fraction, stage_)) cancel();
}

}  // namespace lmrefine
