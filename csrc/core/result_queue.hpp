// result_queue.hpp - bounded queue from the real-time thread (one producer) to the caller (one
// consumer). Behind a live camera the producer never waits: when the queue is full it drops the
// oldest result and counts it, because a warning system wants the newest frame, not a backlog.
// Behind a recording the producer waits for room instead (push_wait), so a replay sees every frame
// and gives the same result however slow its consumer is. The consumer waits with a timeout (from
// Python, cffi has released the GIL around the call).
#pragma once

#include <chrono>
#include <condition_variable>
#include <deque>
#include <mutex>

namespace hw {

template <class T> class ResultQueue {
public:
    explicit ResultQueue(int capacity) : capacity_(capacity < 1 ? 1 : capacity) {}

    void push(T item) {
        std::lock_guard<std::mutex> lock(mu_);
        while (int(items_.size()) >= capacity_) {
            items_.pop_front();
            ++dropped_;
        }
        items_.push_back(std::move(item));
        cv_.notify_one();
    }

    // Waits for room (checking `stop` every 50 ms); returns false if stopped before there was room.
    template <class Flag> bool push_wait(T item, const Flag &stop) {
        std::unique_lock<std::mutex> lock(mu_);
        while (int(items_.size()) >= capacity_) {
            if (stop) return false;
            space_cv_.wait_for(lock, std::chrono::milliseconds(50));
        }
        items_.push_back(std::move(item));
        cv_.notify_one();
        return true;
    }

    // No more items will come; pop() drains what is left and then reports closed.
    void close() {
        std::lock_guard<std::mutex> lock(mu_);
        closed_ = true;
        cv_.notify_all();
    }
    void reopen() {
        std::lock_guard<std::mutex> lock(mu_);
        closed_ = false;
    }

    enum class Pop { Item, Timeout, Closed };
    Pop pop(T &out, int timeout_ms) {
        std::unique_lock<std::mutex> lock(mu_);
        cv_.wait_for(lock, std::chrono::milliseconds(timeout_ms < 0 ? 0 : timeout_ms),
                     [&] { return !items_.empty() || closed_; });
        if (!items_.empty()) {
            out = std::move(items_.front());
            items_.pop_front();
            space_cv_.notify_one();
            return Pop::Item;
        }
        return closed_ ? Pop::Closed : Pop::Timeout;
    }

    long long dropped() const {
        std::lock_guard<std::mutex> lock(mu_);
        return dropped_;
    }
    int depth() const {
        std::lock_guard<std::mutex> lock(mu_);
        return int(items_.size());
    }
    int capacity() const { return capacity_; }

private:
    const int capacity_;
    mutable std::mutex mu_;
    std::condition_variable cv_;        // an item or close() arrived
    std::condition_variable space_cv_;  // an item was popped
    std::deque<T> items_;
    long long dropped_ = 0;
    bool closed_ = false;
};

} // namespace hw
