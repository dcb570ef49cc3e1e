// libFuzzer target for the operator console (daemon/web_server.hpp), on an idle daemon of the
// simulated lab that is never run. The first byte picks the path:
//   even: the rest is one HTTP request, parsed and answered as the server does (answer_raw);
//         every answer is an HTTP/1.1 response whose JSON bodies parse (no byte escapes as an
//         exception, the way one non-UTF-8 byte once ended the daemon);
//   odd:  the rest follows a valid WebSocket handshake as the client's frames, read by a
//         Beast server stream with the console's own message limit until the input ends.
#include <unistd.h>

#include <cstdint>
#include <filesystem>
#include <string>

#include <boost/asio/io_context.hpp>
#include <boost/beast/_experimental/test/stream.hpp>
#include <boost/beast/core/flat_buffer.hpp>
#include <boost/beast/websocket.hpp>
#include <nlohmann/json.hpp>

#include "daemon/control_api.hpp"
#include "daemon/web_server.hpp"
#include "fuzz/fuzz_check.hpp"
#include "fuzz/idle_daemon.hpp"

namespace beast = boost::beast;

namespace {

// One console per process on the idle daemon, deliberately never destroyed (never started: the
// fuzzer calls its request handler directly).
manikind::WebServer& idle_console() {
    static manikind::WebServer* console = [] {
        manikind::ControlOptions api;
        api.token = "fuzz-token-7Hq2Lx9Vb4Rk";
        api.max_message_bytes = 4096;
        manikind::WebOptions web;
        web.port = 8470;
        return new manikind::WebServer(manikind::fuzz::idle_daemon("fuzz-console", "off"), api, web);
    }();
    return *console;
}

void http_request(const std::string& bytes) {
    // A campaign accepted here would run on the daemon's thread and change every later reply.
    if (bytes.find("start_campaign") != std::string::npos || bytes.find("shutdown") != std::string::npos) return;
    const std::string reply = idle_console().answer_raw(bytes);
    if (reply.empty()) return;  // the server would close the connection
    FUZZ_CHECK(reply.rfind("HTTP/1.", 0) == 0);
    const auto body_at = reply.find("\r\n\r\n");
    FUZZ_CHECK(body_at != std::string::npos);
    if (reply.find("Content-Type: application/json") != std::string::npos && body_at + 4 < reply.size())
        FUZZ_CHECK(!nlohmann::json::parse(reply.substr(body_at + 4), nullptr, false).is_discarded());
}

void websocket_frames(const std::string& bytes) {
    boost::asio::io_context io;
    beast::websocket::stream<beast::test::stream> ws(io);
    beast::test::stream peer(io);
    ws.next_layer().connect(peer);
    ws.next_layer().append(
        "GET /ws HTTP/1.1\r\nHost: 127.0.0.1:8470\r\nUpgrade: websocket\r\nConnection: upgrade\r\n"
        "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n");
    ws.next_layer().append(bytes);
    peer.close();  // the input is all there is: reads end with an error, never wait
    ws.read_message_max(manikind::kConsoleWsMaxMessageBytes);
    beast::error_code ec;
    ws.accept(ec);
    if (ec) return;
    beast::flat_buffer incoming;
    for (int frames = 0; frames < 64 && !ec; ++frames) {
        ws.read(incoming, ec);
        FUZZ_CHECK(incoming.size() <= manikind::kConsoleWsMaxMessageBytes);
        incoming.consume(incoming.size());
    }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    if (size == 0) return 0;
    const std::string rest(reinterpret_cast<const char*>(data) + 1, size - 1);
    if (data[0] % 2 == 0) http_request(rest);
    else websocket_frames(rest);
    return 0;
}
