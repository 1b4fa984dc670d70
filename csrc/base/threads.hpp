#pragma once
// Sharing a stage's work among threads: how many it may use, and slots that bound how many run at once.

#include <sched.h>

#include <algorithm>
#include <condition_variable>
#include <mutex>
#include <vector>

namespace hw {

// What a stage asks for, but no more than the cores this process may run on (its CPU affinity: pinned to one
// core, work stays on the calling thread, at the cost it had before threads).
inline int usable_threads(int wanted) {
    cpu_set_t cpus;
    const int cores = sched_getaffinity(0, sizeof cpus, &cpus) == 0 ? CPU_COUNT(&cpus) : 1;
    return std::max(1, std::min(wanted, cores));
}

// n slots (0 .. n-1): a piece of parallel work takes one for as long as it runs (its scratch, e.g. an evaluator of
// its own) and gives it back, so that at most n pieces run at once whatever the thread pool does. The work is cut
// into many small pieces rather than one per thread: a pool's worker that wakes late (TBB's take ~3 ms after
// 100 ms idle, as between detection frames) then leaves the caller nothing to wait for.
class SlotPool {
public:
    explicit SlotPool(int n) {
        for (int i = n - 1; i >= 0; --i) free_.push_back(i);
    }
    int take() {
        std::unique_lock<std::mutex> lock(mu_);
        cv_.wait(lock, [&] { return !free_.empty(); });
        const int s = free_.back();
        free_.pop_back();
        return s;
    }
    void give(int s) {
        {
            std::lock_guard<std::mutex> lock(mu_);
            free_.push_back(s);
        }
        cv_.notify_one();
    }

private:
    std::mutex mu_;
    std::condition_variable cv_;
    std::vector<int> free_;
};

} // namespace hw
