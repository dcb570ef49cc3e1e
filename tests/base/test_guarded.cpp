// A thread's top level survives what escapes its body (base/guarded.hpp).
#include <catch2/catch.hpp>

#include <stdexcept>
#include <thread>

#include "base/guarded.hpp"

TEST_CASE("run_guarded: an exception escaping a thread's body is counted and the body runs again, a return ends it",
          "[base][threads]") {
    const auto before = manikind::escaped_exceptions().load();
    int runs = 0;
    std::thread t([&] {
        manikind::run_guarded("test", [&] {
            ++runs;
            if (runs == 1) throw std::runtime_error("a frame no check foresaw");
            if (runs == 2) throw 42;  // not even a std::exception
        });
    });
    t.join();  // without the guard, std::terminate
    CHECK(runs == 3);
    CHECK(manikind::escaped_exceptions().load() == before + 2);
}
