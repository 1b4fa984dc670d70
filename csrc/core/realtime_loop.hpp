// realtime_loop.hpp - one thread per running pipeline: read a frame, process it, queue the result.
// The thread never calls into Python; trouble with the source becomes health events and counters.
#pragma once

#include "capture/frame_source.hpp"
#include "core/pipeline.hpp"
#include "core/result_queue.hpp"

#include <atomic>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include "include/headway.h"

namespace hw {

class RealtimeLoop {
public:
    RealtimeLoop(Pipeline &pipeline, std::unique_ptr<FrameSource> source, ResultQueue<FrameOutput> &results);
    ~RealtimeLoop();  // stops and joins

    void start();
    void stop();      // idempotent; returns after the thread has ended
    bool running() const { return running_; }
    void fill_health(hw_health &h) const;
    FrameSource &source() { return *source_; }
    // Message of an exception that ended the loop ("" if none).
    std::string failure() const;

private:
    void run();
    void run_frames();
    bool wait_reconnect(double &backoff_s);  // false if asked to stop meanwhile

    Pipeline &pipeline_;
    std::unique_ptr<FrameSource> source_;
    ResultQueue<FrameOutput> &results_;
    const PipelineParams params_;
    std::thread thread_;
    std::atomic<bool> stop_{false};
    std::atomic<bool> running_{false};
    std::mutex stop_mu_;
    std::condition_variable stop_cv_;

    // Health, written by the loop thread, read by the caller.
    std::atomic<int> source_state_{HW_SOURCE_IDLE};
    std::atomic<long long> captured_{0}, processed_{0}, decode_errors_{0}, losses_{0}, reconnects_{0};
    std::atomic<double> last_frame_t_{NAN}, last_progress_{NAN}, last_alive_{NAN};
    std::atomic<float> last_total_ms_{NAN};
    mutable std::mutex failure_mu_;
    std::string failure_;
};

} // namespace hw
