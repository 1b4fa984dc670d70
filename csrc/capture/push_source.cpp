#include "capture/push_source.hpp"

#include <chrono>
#include <stdexcept>

namespace hw {

int PushSource::push(const cv::Mat &img, double t_s) {
    if (img.cols != size_.width || img.rows != size_.height)
        throw std::invalid_argument("pushed frame is " + std::to_string(img.cols) + "x" +
                                    std::to_string(img.rows) + " but the camera is configured as " +
                                    std::to_string(size_.width) + "x" + std::to_string(size_.height) +
                                    " (camera.width/camera.height)");
    Frame f;
    f.gray = to_gray(img).clone();
    f.t_s = t_s;
    std::lock_guard<std::mutex> lock(mu_);
    if (ended_) throw std::invalid_argument("push after push_end: the push source has ended");
    if (!(t_s >= last_t_)) throw std::invalid_argument("pushed frame timestamp goes backwards");
    last_t_ = t_s;
    f.number = next_number_++;
    int dropped = 0;
    while (int(frames_.size()) >= capacity_) {
        frames_.pop_front();
        ++dropped_;
        ++dropped;
    }
    frames_.push_back(std::move(f));
    cv_.notify_one();
    return dropped;
}

void PushSource::end() {
    std::lock_guard<std::mutex> lock(mu_);
    ended_ = true;
    cv_.notify_all();
}

void PushSource::interrupt() {
    std::lock_guard<std::mutex> lock(mu_);
    interrupted_ = true;
    cv_.notify_all();
}

ReadStatus PushSource::read(Frame &out) {
    std::unique_lock<std::mutex> lock(mu_);
    // Wake up now and then even without frames so the loop can notice a stop request.
    cv_.wait_for(lock, std::chrono::milliseconds(50),
                 [&] { return !frames_.empty() || ended_ || interrupted_; });
    if (!frames_.empty()) {
        out = std::move(frames_.front());
        frames_.pop_front();
        return ReadStatus::Ok;
    }
    if (ended_) return ReadStatus::End;
    interrupted_ = false;
    return ReadStatus::Again;
}

} // namespace hw
