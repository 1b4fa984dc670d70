#include "base/worker_pool.hpp"

#include <pthread.h>
#include <sched.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>

namespace hw {

int usable_threads(int wanted) {
    cpu_set_t cpus;
    const int cores = sched_getaffinity(0, sizeof cpus, &cpus) == 0 ? CPU_COUNT(&cpus) : 1;
    return std::max(1, std::min(wanted, cores));
}

WorkerPool::WorkerPool(int threads)
    : threads_(std::max(1, threads)), sync_(std::make_unique<Sync>()), owner_pid_(int(getpid())) {}

WorkerPool::~WorkerPool() {
    if (int(getpid()) != owner_pid_) {
        // a forked child: its copies name threads that do not run in it (joining them, or destroying the locks they
        // waited on, would wait forever), so they are let go
        for (auto &t : workers_) t.detach();
        (void)sync_.release();
        return;
    }
    {
        std::lock_guard<std::mutex> lock(sync_->mu);
        quit_ = true;
    }
    sync_->wake.notify_all();
    for (auto &t : workers_) t.join();
}

void WorkerPool::start(int workers) {
    while (int(workers_.size()) < workers) {
        const int slot = int(workers_.size()) + 1;
        workers_.emplace_back([this, slot] { work(slot); });
    }
}

void WorkerPool::place() {
    const int cpu = sched_getcpu();
    if (cpu < 0 || cpu == placed_cpu_) return;
    cpu_set_t cpus;
    if (sched_getaffinity(0, sizeof cpus, &cpus) != 0) return;
    CPU_CLR(cpu, &cpus);
    if (CPU_COUNT(&cpus) == 0) return;
    for (auto &t : workers_) pthread_setaffinity_np(t.native_handle(), sizeof cpus, &cpus);
    placed_cpu_ = cpu;
}

void WorkerPool::drain(int slot) {
    for (int i; (i = next_.fetch_add(1, std::memory_order_relaxed)) < n_;) {
        try {
            (*job_)(i, slot);
        } catch (...) {
            std::lock_guard<std::mutex> lock(sync_->mu);
            if (!error_) error_ = std::current_exception();
        }
    }
}

void WorkerPool::work(int slot) {
    unsigned long seen = 0;
    for (;;) {
        {
            std::unique_lock<std::mutex> lock(sync_->mu);
            sync_->wake.wait(lock, [&] { return quit_ || generation_ != seen; });
            if (quit_) return;
            seen = generation_;
            // a worker that wakes after the caller has run out of items stays out: the caller waits only for the
            // workers that joined
            if (slot > participants_ || closed_) continue;
            active_.fetch_add(1);
        }
        drain(slot);
        {
            std::lock_guard<std::mutex> lock(sync_->mu);
            if (active_.fetch_sub(1) == 1) sync_->done.notify_one();
        }
    }
}

void WorkerPool::run(int n, const std::function<void(int, int)> &fn) {
    const int t = int(getpid()) == owner_pid_ ? std::min(threads(), n) : 1;  // forked: the workers are not here
    if (t <= 1) {
        for (int i = 0; i < n; ++i) fn(i, 0);
        return;
    }
    start(t - 1);
    place();
    {
        std::lock_guard<std::mutex> lock(sync_->mu);
        job_ = &fn;
        n_ = n;
        next_.store(0);
        error_ = nullptr;
        participants_ = t - 1;
        closed_ = false;
        ++generation_;
    }
    sync_->wake.notify_all();
    drain(0);
    {
        std::lock_guard<std::mutex> lock(sync_->mu);
        closed_ = true;
    }
    // A worker that joined holds at most one item when the caller runs out: wait for it spinning a little (a
    // sleeping caller is woken late, as the workers are), then asleep.
    const auto until = std::chrono::steady_clock::now() + std::chrono::milliseconds(2);
    while (active_.load() > 0 && std::chrono::steady_clock::now() < until) {
    }
    std::unique_lock<std::mutex> lock(sync_->mu);
    sync_->done.wait(lock, [&] { return active_.load() == 0; });
    job_ = nullptr;
    if (error_) std::rethrow_exception(std::exchange(error_, nullptr));
}

} // namespace hw
