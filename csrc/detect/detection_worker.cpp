#include "detect/detection_worker.hpp"

#include "base/stopwatch.hpp"

#include <algorithm>
#include <cerrno>

#include <sched.h>
#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

namespace hw {

DetectionWorker::DetectionWorker() : sync_(std::make_unique<Sync>()), owner_pid_(int(getpid())) {}

DetectionWorker::~DetectionWorker() {
    if (int(getpid()) != owner_pid_) {
        // a forked child: the thread does not run in it (joining it, or destroying the locks it waited on, would wait
        // forever), so it is let go
        if (thread_.joinable()) thread_.detach();
        (void)sync_.release();
        return;
    }
    {
        std::unique_lock<std::mutex> lock(sync_->mu);
        sync_->done.wait(lock, [&] { return !has_job_; });
        quit_ = true;
    }
    sync_->wake.notify_all();
    if (thread_.joinable()) thread_.join();
}

namespace {

id_t this_thread_id() { return id_t(syscall(SYS_gettid)); }

// The nice value of thread `tid` (Linux: nice and the policy are per thread); `fallback` when it cannot be read.
int nice_of(id_t tid, int fallback) {
    errno = 0;
    const int n = getpriority(PRIO_PROCESS, tid);
    return errno == 0 ? n : fallback;
}

// Thread `tid` under SCHED_IDLE (it runs when nothing else wants the core), or SCHED_OTHER at nice value `nice`.
void set_policy(id_t tid, bool idle, int nice) {
    const sched_param none{};
    (void)sched_setscheduler(pid_t(tid), idle ? SCHED_IDLE : SCHED_OTHER, &none);
    if (!idle) (void)setpriority(PRIO_PROCESS, tid, nice);
}

} // namespace

void DetectionWorker::loop() {
    const id_t tid = this_thread_id();
    std::unique_lock<std::mutex> lock(sync_->mu);
    tid_ = int(tid);
    for (;;) {
        sync_->wake.wait(lock, [&] { return quit_ || has_job_; });
        if (!has_job_) return;  // quit, nothing left to run
        // each job starts in the background, also after a wait() raised it; failing (a container's policy) leaves it
        // at the priority it has
        set_policy(tid, true, 0);
        lock.unlock();
        std::exception_ptr error;
        try {
            job_();
        } catch (...) {
            error = std::current_exception();
        }
        lock.lock();
        job_ = nullptr;
        error_ = error;
        has_job_ = false;
        sync_->done.notify_all();
    }
}

void DetectionWorker::run(std::function<void()> job) {
    wait();
    if (int(getpid()) != owner_pid_) {  // forked: no worker thread here
        job();
        return;
    }
    {
        std::lock_guard<std::mutex> lock(sync_->mu);
        job_ = std::move(job);
        has_job_ = true;
    }
    if (!thread_.joinable()) thread_ = std::thread([this] { loop(); });
    sync_->wake.notify_one();
}

float DetectionWorker::wait() {
    if (int(getpid()) != owner_pid_) return 0.f;  // forked: every job ran on the caller
    Stopwatch sw;
    std::exception_ptr error;
    {
        std::unique_lock<std::mutex> lock(sync_->mu);
        // The caller now waits for the job: it runs at the caller's priority until it is done, so that other
        // processes do not hold it up longer than they would the caller (leaving SCHED_IDLE needs the caller's nice
        // value within RLIMIT_NICE, or CAP_SYS_NICE; without them the job stays in the background).
        if (has_job_ && tid_ > 0) set_policy(id_t(tid_), false, nice_of(this_thread_id(), 0));
        sync_->done.wait(lock, [&] { return !has_job_; });
        std::swap(error, error_);
    }
    if (error) std::rethrow_exception(error);
    return sw.ms();
}

bool DetectionWorker::busy() const {
    std::lock_guard<std::mutex> lock(sync_->mu);
    return has_job_;
}

} // namespace hw
