#include "lmrefine/core/parallel.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/partitioner.h>
#include <tbb/task_arena.h>
#include <tbb/task_group.h>

#include <algorithm>
#include <atomic>
#include <cstdlib>
#include <map>
#include <memory>
#include <mutex>
#include <thread>

#include "lmrefine/core/progress.h"

namespace lmrefine {
namespace {

// Set in a child process made by fork(): oneTBB's workers were not copied
// into it and its scheduler may be left holding their locks, so the child
// runs every loop on its own thread.
std::atomic<bool> g_forked_child{false};

// One arena per thread count, kept for the process: the automaton runs
// thousands of short loops and an arena's set-up would be paid for each.
tbb::task_arena& arena_for(int threads) {
    static std::mutex mutex;
    static std::map<int, std::unique_ptr<tbb::task_arena>> arenas;
    std::lock_guard<std::mutex> lock(mutex);
    std::unique_ptr<tbb::task_arena>& arena = arenas[threads];
    if (!arena) arena = std::make_unique<tbb::task_arena>(threads);
    return *arena;
}

}  // namespace

void serial_after_fork() { g_forked_child.store(true); }

int thread_count() {
    if (g_forked_child.load()) return 1;
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

    // One chunk per task, so a chunk's items are the same whatever the
    // thread count (results stay bit-identical).
    const auto run_chunks = [&](int64_t first, int64_t last) {
        for (int64_t chunk = first; chunk != last; ++chunk) {
            if (progress && progress->cancelled()) return;
            const int64_t begin = chunk * grain;
            const int64_t end = std::min(count, begin + grain);
            body(begin, end);
            if (progress) progress->advance(uint64_t(end - begin));
        }
    };
    if (threads <= 1) {
        run_chunks(0, chunks);
        return;
    }
    // An arena of `threads` slots caps this loop (LMREFINE_THREADS) without
    // changing the process-wide scheduler Embree and Blender share. An
    // exception thrown by `body` cancels the loop and is rethrown here.
    arena_for(threads).execute([&] {
        tbb::parallel_for(
            tbb::blocked_range<int64_t>(0, chunks, 1),
            [&](const tbb::blocked_range<int64_t>& range) { run_chunks(range.begin(), range.end()); },
            tbb::simple_partitioner());
    });
}

}  // namespace lmrefine
