// stopwatch.hpp - monotonic time for capture stamps and stage timings.
#pragma once

#include <chrono>

namespace hw {

inline double monotonic_s() {
    using namespace std::chrono;
    return duration<double>(steady_clock::now().time_since_epoch()).count();
}

// Measures one stage: construct, run the stage, call ms().
class Stopwatch {
public:
    Stopwatch() : t0_(std::chrono::steady_clock::now()) {}
    float ms() const {
        return std::chrono::duration<float, std::milli>(std::chrono::steady_clock::now() - t0_).count();
    }

private:
    std::chrono::steady_clock::time_point t0_;
};

} // namespace hw
