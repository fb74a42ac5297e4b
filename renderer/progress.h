// SPDX-License-Identifier: Apache-2.0
// A progress bar on stderr for long renders. Internal to renderer/.
#pragma once
#include <chrono>
#include <condition_variable>
#include <functional>
#include <mutex>
#include <thread>

namespace texcache::internal {

/// Prints a progress bar on stderr once a render has run for a second, from a thread of its own
/// that polls `fraction()` (0..1) every 250 ms; a stderr that is not a terminal (a log file)
/// gets a plain line every 10 s instead. Disabled, it costs nothing.
class Progress {
public:
    Progress(bool enabled, std::function<double()> fraction);
    ~Progress();
    Progress(const Progress&) = delete;
    Progress& operator=(const Progress&) = delete;

private:
    using Clock = std::chrono::steady_clock;
    void Loop();

    std::function<double()> fraction_;
    Clock::time_point start_;
    std::thread thread_;
    std::mutex m_;
    std::condition_variable cv_;
    bool done_ = false, printed_ = false;
    bool tty_;
    double nextLine_ = 0.0;
};

}  // namespace texcache::internal
