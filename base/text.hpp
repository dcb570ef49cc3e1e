#pragma once
// Text from outside (HTTP paths and headers, device replies, file names) is hostile until
// checked: it may hold bytes that are not UTF-8, which nlohmann::json refuses to dump (it
// throws type_error.316). These helpers check it, show it safely, and dump JSON that cannot throw
// on it.
#include <string>
#include <string_view>

#include <nlohmann/json.hpp>

namespace manikind {

// True when `text` is well-formed UTF-8 (RFC 3629: no overlongs, no surrogates, <= U+10FFFF).
bool is_utf8(std::string_view text);

// `text` with every byte that is not part of well-formed UTF-8, and every control character,
// written as \xNN: safe in a log line, an error message or a JSON string.
std::string printable(std::string_view text, std::size_t max_bytes = 200);

// JSON text of `j`; a string inside that is not UTF-8 has its bad bytes replaced by U+FFFD
// instead of throwing.
std::string dump_json(const nlohmann::json& j, int indent = -1);

}  // namespace manikind
