// libFuzzer target for the daemon's configuration (daemon/config.hpp): the input as the
// TOML text over the defaults, then what `manikin config check` does with a parsed config.
// Only UserError may escape: it is what the daemon and the CLI report as bad input.
#include <cstdint>
#include <string>

#include "daemon/config.hpp"
#include "base/user_error.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    const std::string text(reinterpret_cast<const char*>(data), size);
    try {
        const auto config = manikind::config::parse_config(text, "fuzz.toml");
        (void)manikind::config::validate(config);
    } catch (const manikind::UserError&) {
    }
    return 0;
}
