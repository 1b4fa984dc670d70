// WorkerPool: every item runs exactly once whatever thread takes it, the slot handed to each is one of the
// pool's threads, and an exception of an item reaches the caller after the other items ran.
#include "base/worker_pool.hpp"

#include <doctest/doctest.h>

#include <atomic>
#include <stdexcept>
#include <vector>

TEST_CASE("every item runs once, on a slot of the pool") {
    hw::WorkerPool pool(2);
    for (int round = 0; round < 20; ++round) {
        std::vector<std::atomic<int>> runs(500);
        std::atomic<int> bad_slot{0};
        pool.run(500, [&](int item, int slot) {
            runs[size_t(item)]++;
            if (slot < 0 || slot >= 2) bad_slot++;
        });
        int once = 0;
        for (auto &r : runs) once += r.load() == 1;
        CHECK(once == 500);
        CHECK(bad_slot.load() == 0);
    }
}

TEST_CASE("an item's exception is rethrown to the caller and the other items still run") {
    hw::WorkerPool pool(2);
    std::atomic<int> ran{0};
    CHECK_THROWS_WITH_AS(pool.run(100,
                                  [&](int item, int) {
                                      ran++;
                                      if (item == 37) throw std::runtime_error("item 37 failed");
                                  }),
                         "item 37 failed", std::runtime_error);
    CHECK(ran.load() == 100);
    // the pool is usable afterwards
    std::atomic<int> again{0};
    pool.run(10, [&](int, int) { again++; });
    CHECK(again.load() == 10);
}
