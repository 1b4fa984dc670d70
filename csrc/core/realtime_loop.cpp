#include "core/realtime_loop.hpp"

#include "capture/push_source.hpp"
#include "base/stopwatch.hpp"

#include <algorithm>

namespace hw {

RealtimeLoop::RealtimeLoop(Pipeline &pipeline, std::unique_ptr<FrameSource> source,
                           ResultQueue<FrameOutput> &results)
    : pipeline_(pipeline), source_(std::move(source)), results_(results), params_(pipeline.config().pipeline) {}

RealtimeLoop::~RealtimeLoop() { stop(); }

void RealtimeLoop::start() {
    stop_ = false;
    running_ = true;
    results_.reopen();
    source_state_ = SourceState::kRunning;
    thread_ = std::thread([this] { run(); });
}

void RealtimeLoop::stop() {
    {
        std::lock_guard<std::mutex> lock(stop_mu_);
        stop_ = true;
    }
    stop_cv_.notify_all();
    source_->interrupt();
    if (thread_.joinable()) thread_.join();
    running_ = false;
}

std::string RealtimeLoop::failure() const {
    std::lock_guard<std::mutex> lock(failure_mu_);
    return failure_;
}

void RealtimeLoop::run() {
    try {
        run_frames();
    } catch (const std::exception &e) {
        // Nothing may escape a thread; the caller sees the loop ended and the message.
        std::lock_guard<std::mutex> lock(failure_mu_);
        failure_ = e.what();
        source_state_ = SourceState::kFailed;
    }
    running_ = false;  // before close(): whoever sees the end also sees the loop stopped
    results_.close();
}

bool RealtimeLoop::wait_reconnect(double &backoff_s) {
    // Wait in slices so the sign of life keeps coming while the back-off is long.
    const double until = monotonic_s() + backoff_s;
    std::unique_lock<std::mutex> lock(stop_mu_);
    while (!stop_ && monotonic_s() < until) {
        last_alive_ = monotonic_s();
        stop_cv_.wait_for(lock, std::chrono::duration<double>(std::min(0.1, until - monotonic_s())),
                          [&] { return stop_.load(); });
    }
    backoff_s = std::min(backoff_s * 2.0, params_.reconnect_max_s);
    return !stop_;
}

void RealtimeLoop::run_frames() {
    const double started = monotonic_s();
    int pending_events = 0;     // events to report with the next frame
    int consecutive_errors = 0;
    double backoff_s = params_.reconnect_initial_s;
    bool lost = false;
    Frame frame;
    while (!stop_) {
        last_alive_ = monotonic_s();
        if (params_.debug_stall_after_s > 0 && monotonic_s() - started > params_.debug_stall_after_s) {
            // Test hook: hang like a stuck driver call would, until stopped.
            std::unique_lock<std::mutex> lock(stop_mu_);
            stop_cv_.wait(lock, [&] { return stop_.load(); });
            break;
        }
        if (lost) {
            if (!wait_reconnect(backoff_s)) break;
            if (!source_->reopen()) continue;
            lost = false;
            backoff_s = params_.reconnect_initial_s;
            ++reconnects_;
            pending_events |= kEventReconnected;
            source_state_ = SourceState::kRunning;
            continue;
        }
        frame.events = 0;  // the frame is reused: only what happened before this one may be reported with it
        const ReadStatus st = source_->read(frame);
        switch (st) {
        case ReadStatus::Again: continue;
        case ReadStatus::DecodeError:
        case ReadStatus::SizeChanged:
            ++decode_errors_;
            pending_events |= st == ReadStatus::DecodeError ? kEventDecodeError : kEventSizeChanged;
            if (++consecutive_errors >= params_.max_decode_errors) {
                source_state_ = SourceState::kFailed;
                return;
            }
            continue;
        case ReadStatus::Lost:
            if (!source_->live()) {
                source_state_ = SourceState::kFailed;
                return;
            }
            ++losses_;
            lost = true;
            pending_events |= kEventSourceLost;
            source_state_ = SourceState::kReconnecting;
            continue;
        case ReadStatus::End: source_state_ = SourceState::kEnded; return;
        case ReadStatus::Ok: break;
        }
        consecutive_errors = 0;
        ++captured_;
        last_frame_t_ = frame.t_s;
        frame.events |= pending_events;
        pending_events = 0;
        FrameOutput out = pipeline_.process(frame);
        last_total_ms_ = out.total_ms;
        if (source_->paced_by_consumer()) {
            if (!results_.push_wait(std::move(out), stop_)) break;
        } else {
            results_.push(std::move(out));
        }
        ++processed_;
        last_progress_ = monotonic_s();
    }
}

LoopHealth RealtimeLoop::health() const {
    LoopHealth h;
    h.running = running_;
    h.source_state = source_state_;
    h.frames_captured = captured_;
    h.frames_processed = processed_;
    h.results_dropped = results_.dropped();
    auto *push = dynamic_cast<PushSource *>(source_.get());
    h.frames_pushed_dropped = push ? push->dropped() : 0;
    h.decode_errors = decode_errors_;
    h.source_losses = losses_;
    h.reconnects = reconnects_;
    h.last_frame_t_s = last_frame_t_;
    h.last_progress_s = last_progress_;
    h.last_alive_s = running_ ? last_alive_.load() : NAN;
    h.last_total_ms = last_total_ms_;
    h.queue_depth = results_.depth();
    h.queue_capacity = results_.capacity();
    return h;
}

} // namespace hw
