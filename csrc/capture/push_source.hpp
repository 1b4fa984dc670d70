// push_source.hpp - frames handed in by the caller (Python), for tests and custom front ends.
#pragma once

#include "capture/frame_source.hpp"

#include <condition_variable>
#include <deque>
#include <mutex>

namespace hw {

class PushSource final : public FrameSource {
public:
    PushSource(SourceSize size, int capacity) : size_(size), capacity_(capacity) {}

    // Caller thread: copies the frame in (converted to gray). Throws std::invalid_argument on a frame
    // of the wrong size or type. A full queue drops its oldest frame; returns the frames dropped.
    int push(const cv::Mat &img, double t_s);
    void end();
    int64_t dropped() const { return dropped_; }

    ReadStatus read(Frame &out) override;
    void interrupt() override;
    std::string describe() const override { return "pushed frames"; }

private:
    SourceSize size_;
    int capacity_;
    std::mutex mu_;
    std::condition_variable cv_;
    std::deque<Frame> frames_;
    int64_t next_number_ = 0;
    int64_t dropped_ = 0;
    double last_t_ = -1e300;
    bool ended_ = false, interrupted_ = false;
};

} // namespace hw
