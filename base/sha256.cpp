#include "base/sha256.hpp"

#include <array>
#include <stdexcept>

#include <openssl/evp.h>

#include "base/lazy_library.hpp"

namespace manikind {

namespace {

// libcrypto, loaded by the first fingerprint rather than at every program's start
// (base/lazy_library.hpp): `manikin --version` and `status` never hash anything.
struct Crypto {
    decltype(&::EVP_Digest) Digest = nullptr;
    decltype(&::EVP_sha256) sha256 = nullptr;
};

const Crypto& crypto() {
    static LazyLibrary library("libmanikind-crypto.so", "OpenSSL's libcrypto (for SHA-256 fingerprints)");
    return library.table<Crypto>([](LazyLibrary& l, Crypto& a) {
        MANIKIND_BIND(l, a, Digest, EVP_Digest);
        MANIKIND_BIND(l, a, sha256, EVP_sha256);
    });
}

}  // namespace

// FIPS 180-4 SHA-256 from OpenSSL's libcrypto (Debian's libssl-dev, which libpq already needs):
// a hash is not something to write again.
std::string sha256_hex(std::string_view bytes) {
    const Crypto& c = crypto();
    std::array<unsigned char, EVP_MAX_MD_SIZE> digest{};
    unsigned int digest_bytes = 0;
    if (c.Digest(bytes.data(), bytes.size(), digest.data(), &digest_bytes, c.sha256(), nullptr) != 1 || digest_bytes != 32)
        throw std::runtime_error("SHA-256: libcrypto's EVP_Digest failed");
    static constexpr char hex[] = "0123456789abcdef";
    std::string out;
    out.reserve(2 * digest_bytes);
    for (unsigned int i = 0; i < digest_bytes; ++i) {
        out.push_back(hex[digest[i] >> 4]);
        out.push_back(hex[digest[i] & 0x0f]);
    }
    return out;
}

}  // namespace manikind
