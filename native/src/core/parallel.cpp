#include "lmrefine/core/parallel.h"

#include <pthread.h>

#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <cstdlib>
#include <exception>
#include <mutex>
#include <thread>
#include <vector>

#include "lmrefine/core/progress.h"

namespace lmrefine {
namespace {

// True on a pool worker, and on a caller while its loop runs: a parallel_for
// nested inside another's body runs serially instead of waiting for workers
// that are busy with the outer loop.
thread_local bool t_inside_loop = false;

// Workers that live for the whole process. The automaton runs a few
// parallel loops per step and hundreds of steps; starting threads for each
// loop cost more than the work at its coarse levels.
class WorkerPool {
public:
    // Runs `work` on `participants - 1` workers and on the calling thread,
    // and returns when all of them are done.
    void run(int participants, const std::function<void()>& work) {
        std::unique_lock<std::mutex> lock(mutex_);
        while (int(workers_.size()) < participants - 1) {
            const int index = int(workers_.size());
            workers_.emplace_back([this, index] { serve(index); });
        }
        job_ = &work;
        wanted_ = participants - 1;
        running_ = wanted_;
        ++generation_;
        lock.unlock();
        wake_.notify_all();
        work();
        lock.lock();
        done_.wait(lock, [this] { return running_ == 0; });
        job_ = nullptr;
    }

    // One loop at a time uses the pool; a loop started meanwhile (another
    // Python thread) runs on its own thread.
    std::mutex& busy() { return busy_; }

private:
    void serve(int index) {
        t_inside_loop = true;
        uint64_t seen = 0;
        std::unique_lock<std::mutex> lock(mutex_);
        for (;;) {
            wake_.wait(lock, [&] { return generation_ != seen; });
            seen = generation_;
            if (index >= wanted_) continue;
            const std::function<void()>* job = job_;
            lock.unlock();
            (*job)();
            lock.lock();
            if (--running_ == 0) done_.notify_one();
        }
    }

    std::mutex mutex_, busy_;
    std::condition_variable wake_, done_;
    std::vector<std::thread> workers_;
    const std::function<void()>* job_ = nullptr;
    uint64_t generation_ = 0;
    int wanted_ = 0, running_ = 0;
};

// The process's pool, made on first use. After a fork the child has none of
// the parent's threads, so it makes a new pool (the old one is left behind:
// its mutexes may be held by threads that do not exist in the child).
std::atomic<WorkerPool*> g_pool{nullptr};

WorkerPool& pool() {
    static std::once_flag registered;
    std::call_once(registered, [] { pthread_atfork(nullptr, nullptr, [] { g_pool.store(nullptr); }); });
    WorkerPool* existing = g_pool.load();
    if (existing) return *existing;
    static std::mutex creating;
    std::lock_guard<std::mutex> lock(creating);
    if (!g_pool.load()) g_pool.store(new WorkerPool());  // lives as long as the process
    return *g_pool.load();
}

}  // namespace

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

    const std::function<void()> worker = [&]() {
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

    std::unique_lock<std::mutex> busy;
    if (threads > 1 && !t_inside_loop) busy = std::unique_lock<std::mutex>(pool().busy(), std::try_to_lock);
    if (busy.owns_lock()) {
        struct Inside {  // reset even if starting a worker throws
            Inside() { t_inside_loop = true; }
            ~Inside() { t_inside_loop = false; }
        } inside;
        pool().run(threads, worker);
    } else {
        worker();
    }
    if (error) std::rethrow_exception(error);
}

}  // namespace lmrefine
