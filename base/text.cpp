#include "base/text.hpp"

#include <fmt/format.h>

namespace manikind {

namespace {

// Length of the well-formed UTF-8 sequence at text[i], or 0 (RFC 3629 section 4's table).
std::size_t utf8_sequence(std::string_view text, std::size_t i) {
    const auto byte = [&](std::size_t k) { return static_cast<unsigned char>(text[k]); };
    const unsigned char b0 = byte(i);
    if (b0 < 0x80) return 1;
    std::size_t n = 0;
    unsigned char lo = 0x80, hi = 0xBF;  // the range of the second byte
    if (b0 >= 0xC2 && b0 <= 0xDF) n = 2;
    else if (b0 == 0xE0) n = 3, lo = 0xA0;
    else if ((b0 >= 0xE1 && b0 <= 0xEC) || b0 == 0xEE || b0 == 0xEF) n = 3;
    else if (b0 == 0xED) n = 3, hi = 0x9F;  // no UTF-16 surrogates
    else if (b0 == 0xF0) n = 4, lo = 0x90;
    else if (b0 >= 0xF1 && b0 <= 0xF3) n = 4;
    else if (b0 == 0xF4) n = 4, hi = 0x8F;  // nothing above U+10FFFF
    else return 0;
    if (i + n > text.size()) return 0;
    if (byte(i + 1) < lo || byte(i + 1) > hi) return 0;
    for (std::size_t k = 2; k < n; ++k)
        if (byte(i + k) < 0x80 || byte(i + k) > 0xBF) return 0;
    return n;
}

}  // namespace

bool is_utf8(std::string_view text) {
    for (std::size_t i = 0; i < text.size();) {
        const std::size_t n = utf8_sequence(text, i);
        if (n == 0) return false;
        i += n;
    }
    return true;
}

namespace {

// The first control character in `text` (UTF-8 already checked): C0 but the `allowed` ones, DEL,
// or a C1 control (U+0080..U+009F, encoded C2 80..C2 9F), which terminals act on too.
bool has_control(std::string_view text, std::string_view allowed) {
    for (std::size_t i = 0; i < text.size(); ++i) {
        const auto c = static_cast<unsigned char>(text[i]);
        if ((c < 0x20 && allowed.find(static_cast<char>(c)) == std::string_view::npos) || c == 0x7F) return true;
        if (c == 0xC2 && i + 1 < text.size() && static_cast<unsigned char>(text[i + 1]) <= 0x9F) return true;
    }
    return false;
}

}  // namespace

std::string label_problem(std::string_view value, std::size_t max_bytes, bool path_safe) {
    if (value.empty()) return "empty";
    if (!is_utf8(value)) return "not UTF-8 text";
    if (value.size() > max_bytes) return fmt::format("{} bytes, more than the {} allowed", value.size(), max_bytes);
    if (has_control(value, {})) return "holds a control character (a line break, NUL, escape, ...)";
    if (path_safe && value.find_first_of("/\\") != std::string_view::npos) return "holds '/' or '\\' (it names a folder in exports)";
    if (value.find_first_not_of(" \t") == std::string_view::npos) return "only spaces";
    return {};
}

std::string text_problem(std::string_view value, std::size_t max_bytes) {
    if (!is_utf8(value)) return "not UTF-8 text";
    if (value.size() > max_bytes) return fmt::format("{} bytes, more than the {} allowed", value.size(), max_bytes);
    if (has_control(value, "\n\t")) return "control characters are not allowed (newlines and tabs are)";
    if (value.find_first_not_of(" \t\n") == std::string_view::npos) return "empty";
    return {};
}

std::string printable(std::string_view text, std::size_t max_bytes) {
    std::string out;
    std::size_t i = 0;
    for (; i < text.size() && i < max_bytes;) {
        const std::size_t n = utf8_sequence(text, i);
        const auto b = static_cast<unsigned char>(text[i]);
        if (n == 0 || (n == 1 && (b < 0x20 || b == 0x7F))) {
            out += fmt::format("\\x{:02X}", b);
            ++i;
        } else {
            out.append(text.substr(i, n));
            i += n;
        }
    }
    if (i < text.size()) out += fmt::format("... ({} bytes)", text.size());
    return out;
}

std::string dump_json(const nlohmann::json& j, int indent) {
    return j.dump(indent, ' ', false, nlohmann::json::error_handler_t::replace);
}

}  // namespace manikind
