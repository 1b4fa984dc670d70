#pragma once
// How many threads a stage may use: what it asks for, but no more than the cores this process may run on (its CPU
// affinity: pinned to one core, work stays on the calling thread, at the cost it had before threads).

#include <sched.h>

#include <algorithm>

namespace hw {

inline int usable_threads(int wanted) {
    cpu_set_t cpus;
    const int cores = sched_getaffinity(0, sizeof cpus, &cpus) == 0 ? CPU_COUNT(&cpus) : 1;
    return std::max(1, std::min(wanted, cores));
}

} // namespace hw
