// A work-sharing loop over all cores on oneTBB (the scheduler Embree already
// loads). The calling thread takes part, so it keeps reporting progress (and
// Python keeps seeing Ctrl-C). docs/architecture.md says why oneTBB.
#pragma once

#include <cstdint>
#include <functional>

namespace lmrefine {

class Progress;

// Number of worker threads: LMREFINE_THREADS if set, else all hardware
// threads; 1 in a child made by fork() (see serial_after_fork).
int thread_count();

// Called in a child process right after fork() (the Python package registers
// it with os.register_at_fork): from then on every loop runs serially, since
// oneTBB does not survive a fork taken while its workers run.
void serial_after_fork();

// Calls body(begin, end) on disjoint chunks of [0, count) of about `grain`
// items, on all threads. Chunks are handed out dynamically, so `body` must
// make each index's result independent of which thread ran it (that keeps
// results deterministic). If `progress` is given, each finished chunk
// advances it by its size, and no new chunk starts once it is cancelled
// (the caller then calls progress->check()). An exception thrown by `body`
// stops the loop and is rethrown on the calling thread.
void parallel_for(int64_t count, int64_t grain,
                  const std::function<void(int64_t begin, int64_t end)>& body,
                  Progress* progress = nullptr);

}  // namespace lmrefine
