#include "lmrefine/parallel.h"

#include <algorithm>
#include <atomic>
#include <cstdlib>
#include <exception>
#include <mutex>
#include <thread>
#include <vector>

#include "lmrefine/progress.h"

namespace lmrefine {

int thread_count() {
    if (const char* env = std::getenv("LMREFINE_THREADS")) {
        const int n = std::atoi(env);
        if (n > 0) return n;
    }
    return std::max(1u, std::thread::hardware_concurrency());
}

void parallel_for(int64_t count, int64_t grain,
                  const std::function<void(int64_t, int64_t)>& body, Progress* progress) {
    if (count <= 0) return;
    grain = std::max<int64_t>(1, grain);
    const int64_t chunks = (count + grain - 1) / grain;
    const int threads = int(std::min<int64_t>(thread_count(), chunks));

    std::atomic<int64_t> next{0};
    std::atomic<bool> failed{false};
    std::exception_ptr error;
    std::mutex error_mutex;

    auto worker = [&]() {
        for (;;) {
            if (failed.load(std::memory_order_relaxed)) return;
            if (progress && progress->cancelled()) return;
            const int64_t chunk = next.fetch_add(1);
            if (chunk >= chunks) return;
            const int64_t begin = chunk * grain;
            const int64_t end = std::min(count, begin + grain);
            try {
                body(begin, end);
            } catch (...) {
                std::lock_guard<std::mutex> lock(error_mutex);
                if (!error) error = std::current_exception();
                failed.store(true);
                return;
            }
            if (progress) progress->advance(uint64_t(end - begin));
        }
    };

    std::vector<std::thread> pool;
    pool.reserve(threads > 0 ? threads - 1 : 0);
    for (int i = 1; i < threads; ++i) pool.emplace_back(worker);
    worker();
    for (auto& t : pool) t.join();
    if (error) std::rethrow_exception(error);
}

}  // namespace lmrefine
