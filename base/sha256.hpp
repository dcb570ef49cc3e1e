#pragma once
// SHA-256 (FIPS 180-4, from libcrypto) of a byte string, as lowercase hex: the configuration's fingerprint in
// exports' provenance, comparable with `sha256sum manikind.toml`. No I/O.
#include <string>
#include <string_view>

namespace manikind {

std::string sha256_hex(std::string_view bytes);

}  // namespace manikind
