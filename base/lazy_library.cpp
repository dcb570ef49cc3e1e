#include "base/lazy_library.hpp"

#include <dlfcn.h>
#include <unistd.h>

#include <array>
#include <filesystem>

#include <fmt/format.h>

#include "base/user_error.hpp"

namespace manikind {

LazyLibrary::LazyLibrary(std::string module_file, std::string what)
    : module_file_(std::move(module_file)), what_(std::move(what)) {}

std::string LazyLibrary::program_directory() {
    std::array<char, 4096> buf{};
    const auto n = ::readlink("/proc/self/exe", buf.data(), buf.size() - 1);
    if (n <= 0) return ".";
    return std::filesystem::path(std::string(buf.data(), static_cast<std::size_t>(n))).parent_path().string();
}

void LazyLibrary::load() {
    const std::string dir = program_directory();
    const std::array<std::string, 2> candidates{dir + "/" + module_file_, dir + "/../lib/manikind/" + module_file_};
    std::string reasons;
    for (const auto& path : candidates) {
        std::error_code ec;
        if (!std::filesystem::exists(path, ec)) {
            reasons += fmt::format("{}{}: not there", reasons.empty() ? "" : "; ", path);
            continue;
        }
        // RTLD_NOW: a missing symbol in the library is found here, once, not at some later call.
        // RTLD_LOCAL: its symbols stay out of the program's global namespace.
        if ((handle_ = ::dlopen(path.c_str(), RTLD_NOW | RTLD_LOCAL)) != nullptr) return;
        const char* why = ::dlerror();
        reasons += fmt::format("{}{}: {}", reasons.empty() ? "" : "; ", path, why ? why : "cannot be loaded");
    }
    throw UserError(fmt::format("{} is needed here and could not be loaded ({}); it is built beside the "
                                "program (cmake --build), or installed with its Debian package",
                                what_, reasons),
                    "missing_library");
}

void* LazyLibrary::symbol(const char* name) {
    std::call_once(once_, [this] { load(); });  // an exception leaves once_ unset: the next call retries
    ::dlerror();
    void* address = ::dlsym(handle_, name);
    if (!address) {
        const char* why = ::dlerror();
        throw UserError(fmt::format("{}: the library has no '{}' ({})", what_, name, why ? why : "not found"),
                        "missing_library");
    }
    return address;
}

}  // namespace manikind
