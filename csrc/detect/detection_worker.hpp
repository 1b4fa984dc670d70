#pragma once
// detection_worker.hpp - one thread that runs a frame's detection while the frame thread goes on with the next frames.
//
// Why: a full detection (the cascade's scan and the CNN verifier: about 32 ms at 640x480) does not fit in one frame's
// latency budget, and spread over the frames between detections it does not fit their median either. On its own
// thread it uses the time the frame thread leaves between camera frames; the tracker takes its result at a fixed
// later frame (phd.detect_lag), so what is tracked does not depend on the machine, only how long the frame thread
// waits there does.
//
// The thread runs under SCHED_IDLE: on a shared core it never delays the frame thread, which preempts it as soon as
// a frame arrives (at a low nice value instead, the worker woken by a new job still took a slice of the frame's time:
// docs/decisions.md). While the caller waits for it, it runs at the caller's priority (SCHED_OTHER, the caller's nice
// value), so that other processes hold it up no more than the caller. One job at a time: run() starts it, wait() returns when
// it is done (rethrowing what it threw). The job must own what it reads (copies), as the caller goes on. In a process
// forked after the thread started (which has only the forking thread), run() runs the job on the caller.

#include <condition_variable>
#include <exception>
#include <functional>
#include <memory>
#include <mutex>
#include <thread>

namespace hw {

class DetectionWorker {
public:
    DetectionWorker();
    ~DetectionWorker();  // waits for a running job, then stops and joins the thread
    DetectionWorker(const DetectionWorker &) = delete;
    DetectionWorker &operator=(const DetectionWorker &) = delete;

    // Starts `job` on the worker thread. A job still running is waited for first.
    void run(std::function<void()> job);
    // Returns when the job started last is done (at once when none runs); ms the caller waited. Rethrows the job's
    // exception.
    float wait();
    bool busy() const;

private:
    void loop();

    std::thread thread_;
    // The locks, held apart: a forked child leaves them behind instead of destroying them (as base/worker_pool.hpp).
    struct Sync {
        std::mutex mu;
        std::condition_variable wake, done;
    };
    std::unique_ptr<Sync> sync_;
    std::function<void()> job_;
    bool has_job_ = false, quit_ = false;
    std::exception_ptr error_;
    int owner_pid_ = 0;
    int tid_ = 0;  // the worker thread's kernel id, once it runs
};

} // namespace hw
