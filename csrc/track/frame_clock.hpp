// frame_clock.hpp - the time between a tracker's frames, and the gaps after which its predictions are void.
#pragma once

namespace hw {

class FrameClock {
public:
    explicit FrameClock(double max_dt_s) : max_dt_s_(max_dt_s) {}
    // The time since the previous frame, s (0 on the first). A step back in time or one longer than max_dt_s is a
    // gap: `gap` is set and 0 returned (the tracker starts again from this frame).
    double step(double t_s, bool &gap) {
        double dt = started_ ? t_s - last_t_s_ : 0.0;
        gap = dt < 0.0 || dt > max_dt_s_;
        if (gap) dt = 0.0;
        started_ = true;
        last_t_s_ = t_s;
        return dt;
    }
    void reset() { started_ = false; }

private:
    double max_dt_s_;
    double last_t_s_ = 0.0;
    bool started_ = false;
};

} // namespace hw
