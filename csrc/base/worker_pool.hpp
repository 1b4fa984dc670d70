#pragma once
// worker_pool.hpp - a stage's own threads: its items shared between the calling thread and workers that sleep
// between calls, each worker kept off the core the caller runs on.
//
// Why not OpenCV's parallel_for_ (TBB) (measured, docs/decisions.md): between two camera frames the
// cores idle, and a worker woken then is placed by the kernel on the waker's own core (wake-affine), where it
// shares the caller's core instead of using the idle one. A 10 ms job in 50 pieces, every 30 ms: 8.5 ms on one
// thread, 9.8 ms with a woken worker left where the kernel puts it, 4.9-5.1 ms with the worker kept off the
// caller's core; back to back (no idle) both pools gain. So before each call the workers' CPU affinity is set to
// the cores the caller may use less the one it runs on (a system call only when the caller moved).
//
// Items are taken one at a time from a shared counter: a worker that wakes late leaves the caller nothing to wait
// for. fn(item, slot) gets the slot of the thread running it (0: the caller, 1 .. threads()-1: the workers), for
// scratch of its own; what an item writes must depend on the item only, so that the result is the same whoever
// runs it.

#include <atomic>
#include <condition_variable>
#include <exception>
#include <functional>
#include <memory>
#include <mutex>
#include <thread>
#include <utility>
#include <vector>

namespace hw {

// What a stage asks for, but no more than the cores this thread may run on (its CPU affinity: pinned to one core,
// work stays on the calling thread, at the cost it had before threads).
int usable_threads(int wanted);

class WorkerPool {
public:
    // `threads`: the most that ever share a call, the caller included (1: the caller alone, no worker is started).
    explicit WorkerPool(int threads = 1);
    ~WorkerPool();
    WorkerPool(const WorkerPool &) = delete;
    WorkerPool &operator=(const WorkerPool &) = delete;

    // the threads a call would use now: at most threads, at most the cores the caller may run on
    int threads() const { return usable_threads(threads_); }
    // fn(item, slot) for every item 0 .. n-1; returns when all are done. An exception thrown by fn is rethrown
    // here (the first one; the other items still run). Not reentrant: one caller at a time. In a process forked
    // after the workers started (which has only the forking thread) everything runs on the caller.
    void run(int n, const std::function<void(int item, int slot)> &fn);

private:
    void work(int slot);                   // a worker's loop
    void drain(int slot);                  // take and run items until none is left
    void place();                          // workers off the caller's core
    void start(int workers);               // workers 1 .. workers, started on first need

    int threads_ = 1;
    std::vector<std::thread> workers_;
    // The locks, held apart: a forked child leaves them behind instead of destroying them (a condition variable the
    // parent's workers waited on is never free in the child, and destroying it would wait forever).
    struct Sync {
        std::mutex mu;
        std::condition_variable wake, done;
    };
    std::unique_ptr<Sync> sync_;
    unsigned long generation_ = 0;         // one per call; a worker runs each generation once
    int participants_ = 0;                 // workers (slots 1 .. participants_) in the current call
    std::atomic<int> active_{0};           // workers inside the current call (changed under sync_->mu)
    bool closed_ = true;                   // the caller has run out of items: no worker joins any more
    bool quit_ = false;
    const std::function<void(int, int)> *job_ = nullptr;
    std::atomic<int> next_{0};
    int n_ = 0;
    std::exception_ptr error_;
    int placed_cpu_ = -1;                  // the caller's core the workers were last kept off
    int owner_pid_ = 0;                    // the process the workers run in (a forked child has none of them)
};

} // namespace hw
