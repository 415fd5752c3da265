// Progress reporting that doubles as a cancellation token (as in Open Image
// Denoise): a long call advances it, the callback sees the fraction done and
// may return false to cancel; workers poll cancelled() and stop early.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <mutex>
#include <string>
#include <thread>

namespace lmrefine {

class Progress {
public:
    // fraction in [0, 1] of the current stage; return false to cancel.
    using Callback = std::function<bool(double fraction, const std::string& stage)>;

    Progress() = default;
    explicit Progress(Callback callback, double min_interval_seconds = 0.1);

    Progress(const Progress&) = delete;
    Progress& operator=(const Progress&) = delete;

    // Starts a named stage of `total` units of work and reports 0.
    void begin(const std::string& stage, uint64_t total);
    // Thread-safe and cheap. Only the thread that created the Progress calls
    // the callback (Python can only check for Ctrl-C on its main thread), at
    // most once per interval; other threads just count.
    void advance(uint64_t units = 1);
    // Reports the current stage as complete.
    void finish();

    bool cancelled() const { return cancelled_.load(std::memory_order_relaxed); }
    void cancel() { cancelled_.store(true, std::memory_order_relaxed); }
    // Throws Cancelled if cancellation was requested.
    void check() const;

    double fraction() const;
    const std::string& stage() const { return stage_; }

private:
    void report(double fraction);

    Callback callback_;
    std::chrono::steady_clock::duration min_interval_{};
    std::chrono::steady_clock::time_point last_report_{};
    std::thread::id owner_ = std::this_thread::get_id();
    std::string stage_;
    std::atomic<uint64_t> done_{0};
    uint64_t total_ = 0;
    std::atomic<bool> cancelled_{false};
};

}  // namespace lmrefine
