// SPDX-License-Identifier: Apache-2.0
#include "renderer/progress.h"

#include <unistd.h>

#include <algorithm>
#include <cstdio>

namespace texcache::internal {

Progress::Progress(bool enabled, std::function<double()> fraction)
    : fraction_(std::move(fraction)), start_(Clock::now()), tty_(isatty(fileno(stderr)) != 0) {
    if (enabled) thread_ = std::thread([this] { Loop(); });
}

Progress::~Progress() {
    {
        std::lock_guard<std::mutex> lock(m_);
        done_ = true;
    }
    cv_.notify_all();
    if (thread_.joinable()) thread_.join();
    if (printed_) std::fprintf(stderr, "\n");
}

void Progress::Loop() {
    std::unique_lock<std::mutex> lock(m_);
    while (!cv_.wait_for(lock, std::chrono::milliseconds(250), [this] { return done_; })) {
        const double t = std::chrono::duration<double>(Clock::now() - start_).count();
        if (t < 1.0) continue;
        const double f = std::clamp(fraction_(), 0.0, 1.0);
        const double eta = f > 0.0 ? t / f - t : 0.0;
        if (!tty_) {
            // A log file gets a plain line every 10 s, not a redrawn bar every 250 ms.
            if (t < nextLine_) continue;
            nextLine_ = t + 10.0;
            std::fprintf(stderr, "render %3d%%  %.0fs elapsed, %.0fs left\n", int(f * 100.0), t,
                         eta);
            continue;
        }
        const int w = 30, n = int(f * w);
        std::fprintf(stderr, "\rrender [%.*s%*s] %3d%%  %.1fs elapsed, %.1fs left  ", n,
                     "==============================", w - n, "", int(f * 100.0), t, eta);
        std::fflush(stderr);
        printed_ = true;
    }
}

}  // namespace texcache::internal
