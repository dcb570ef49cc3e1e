#pragma once
// A thread's top level (issue 30: no exception from storage, JSON or a codec leaves any thread).
// An exception that escapes a thread ends the process (std::terminate): recording and control
// gone for one bad frame. run_guarded runs the thread's body again after one escapes, says so on
// stderr with the thread's name, and counts it (escaped_exceptions(), in the daemon's status), so
// the handler is lost and the thread goes on. The body returns normally to end the thread.
#include <atomic>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <exception>
#include <thread>

namespace manikind {

inline std::atomic<std::uint64_t>& escaped_exceptions() {
    static std::atomic<std::uint64_t> count{0};
    return count;
}

template <class Body>
void run_guarded(const char* thread_name, Body&& body) noexcept {
    for (;;) {
        try {
            body();
            return;
        } catch (const std::exception& e) {
            std::fprintf(stderr, "manikind: internal error in the %s thread, which goes on: %s\n", thread_name, e.what());
        } catch (...) {
            std::fprintf(stderr, "manikind: internal error in the %s thread, which goes on: an unknown exception\n",
                         thread_name);
        }
        ++escaped_exceptions();
        // Not a hot loop if the body fails at once each time: a pause a person would not notice.
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
}

}  // namespace manikind
