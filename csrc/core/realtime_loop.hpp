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

namespace hw {

// State of the frame source feeding the loop.
enum class SourceState { kIdle, kRunning, kReconnecting, kEnded, kFailed };

// What the loop reports about itself; abi.cpp turns it into hw_health.
struct LoopHealth {
    bool running = false;            // the real-time thread runs
    SourceState source_state = SourceState::kIdle;
    long long frames_captured = 0;   // frames read from the source
    long long frames_processed = 0;
    long long results_dropped = 0;   // results dropped because the queue to the caller was full
    long long frames_pushed_dropped = 0;  // pushed frames dropped because the push queue was full
    long long decode_errors = 0;
    long long source_losses = 0;
    long long reconnects = 0;
    double last_frame_t_s = NAN;     // s; capture time of the last frame
    double last_progress_s = NAN;    // s, monotonic; the loop last finished a frame
    double last_alive_s = NAN;       // s, monotonic; the loop last went round (NaN if not running)
    float last_total_ms = NAN;       // ms; the last frame's processing time
    int queue_depth = 0;
    int queue_capacity = 0;
};

class RealtimeLoop {
public:
    RealtimeLoop(Pipeline &pipeline, std::unique_ptr<FrameSource> source, ResultQueue<FrameOutput> &results);
    ~RealtimeLoop();  // stops and joins

    void start();
    void stop();      // idempotent; returns after the thread has ended
    bool running() const { return running_; }
    LoopHealth health() const;
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
    std::atomic<SourceState> source_state_{SourceState::kIdle};
    std::atomic<long long> captured_{0}, processed_{0}, decode_errors_{0}, losses_{0}, reconnects_{0};
    std::atomic<double> last_frame_t_{NAN}, last_progress_{NAN}, last_alive_{NAN};
    std::atomic<float> last_total_ms_{NAN};
    mutable std::mutex failure_mu_;
    std::string failure_;
};

} // namespace hw
