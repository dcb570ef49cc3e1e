// The one translation unit that holds Catch2's main; every suite links this object.
//
// A filter that matches no test case fails the run (as -w NoTests would; Catch2 v2 takes one -w,
// and CTest passes -w NoAssertions). A test name with ";" is split by CTest into names that match
// nothing: 15 test cases so named had passed for waves without running.
#define CATCH_CONFIG_RUNNER
#include <catch2/catch.hpp>

#include "base/heap.hpp"

int main(int argc, char* argv[]) {
    manikind::keep_freed_memory_for_reuse();  // base/heap.hpp: the suites run reconcile in-process
    Catch::Session session;
    if (const int rc = session.applyCommandLine(argc, argv); rc != 0) return rc;
    auto& data = session.configData();
    data.warnings = static_cast<Catch::WarnAbout::What>(data.warnings | Catch::WarnAbout::NoTests);
    return session.run();
}
