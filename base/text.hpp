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

// One rule for every name and text that reaches the daemon from outside (the control API, the
// console, a campaign file, the CLI; issue 60): why `value` cannot be used, or empty when it can.
// A label (a campaign's name, an ensemble's id, a note's author) is well-formed UTF-8 of 1 to
// `max_bytes` bytes with no control character (C0, DEL, C1) and, when `path_safe` (it becomes a
// folder or file name in exports), no '/' or '\\'. A text (a note) may also hold newlines and tabs.
std::string label_problem(std::string_view value, std::size_t max_bytes, bool path_safe = false);
std::string text_problem(std::string_view value, std::size_t max_bytes);

// JSON text of `j`; a string inside that is not UTF-8 has its bad bytes replaced by U+FFFD
// instead of throwing.
std::string dump_json(const nlohmann::json& j, int indent = -1);

}  // namespace manikind
