#pragma once
// The control API's client (docs/daemon.md, "Control API"): the one way `manikin` talks to a
// running daemon. Newline-delimited JSON over the daemon's Unix socket; nothing here knows the
// daemon's insides.
#include <sys/un.h>

#include <filesystem>
#include <string>

#include <nlohmann/json.hpp>

namespace manikind {

// The address of a Unix socket path; throws UserError naming `what` when the path is too long
// for sockaddr_un (107 characters).
struct sockaddr_un unix_address(const std::string& path, const std::string& what);

// Client side (the `manikin` CLI): sends one request, returns the reply. Throws UserError when
// the daemon is not reachable, or has not answered within `timeout_s` (saying what it waited for).
nlohmann::json call_daemon(const std::filesystem::path& socket_path, const nlohmann::json& request,
                           double timeout_s = 10.0);

// The token a daemon wrote beside its socket (<socket>.token), or "" when there is none.
std::string read_token_file(const std::filesystem::path& socket_path);

}  // namespace manikind
