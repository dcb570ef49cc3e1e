// The operator console's cost (issue 15): the daemon on the simulated lab in real time with the
// console serving one WebSocket client, against the same daemon without the console (the floor,
// measured in the same run). Prints CPU as % of one core over the window, and each update's
// latency from the newest sample in it to its arrival at the client.
//   bench_console [seconds per configuration, default 20]
#include <sys/resource.h>

#include <boost/asio/connect.hpp>
#include <boost/asio/io_context.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/websocket.hpp>
#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "daemon/control_api.hpp"
#include "daemon/lab_daemon.hpp"
#include "daemon/web_server.hpp"

namespace fs = std::filesystem;
using namespace manikind;

namespace {

double cpu_seconds() {
    rusage u{};
    ::getrusage(RUSAGE_SELF, &u);
    return static_cast<double>(u.ru_utime.tv_sec + u.ru_stime.tv_sec) + 1e-6 * static_cast<double>(u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

double utc_ms_now() {
    return static_cast<double>(
        std::chrono::duration_cast<std::chrono::microseconds>(std::chrono::system_clock::now().time_since_epoch()).count()) *
           1e-3;
}

struct Run {
    double cpu_percent = 0;
    std::vector<double> latency_ms;
};

config::Config lab_config(const fs::path& dir) {
    auto c = config::default_config();
    c.database = dir / "d.db";
    c.simulation.runtime_dir = (dir / "sim").string();
    c.log_level = "error";
    return c;
}

Run measure(const fs::path& dir, bool with_console, double seconds) {
    fs::remove_all(dir);
    fs::create_directories(dir);
    LabDaemon daemon({lab_config(dir), false, 1.0});
    daemon.start_realtime();
    ControlOptions api;
    api.socket_path = dir / "d.sock";
    std::unique_ptr<WebServer> console;
    Run run;
    // Let start-up (device connects, first polls) pass before the window opens.
    std::this_thread::sleep_for(std::chrono::seconds(3));
    if (!with_console) {
        const double cpu0 = cpu_seconds();
        std::this_thread::sleep_for(std::chrono::duration<double>(seconds));
        run.cpu_percent = 100.0 * (cpu_seconds() - cpu0) / seconds;
        daemon.stop();
        return run;
    }
    WebOptions w;
    w.port = 0;
    console = std::make_unique<WebServer>(daemon, api, w);
    console->start();
    namespace beast = boost::beast;
    boost::asio::io_context io;
    boost::asio::ip::tcp::resolver resolver(io);
    beast::websocket::stream<boost::asio::ip::tcp::socket> ws(io);
    boost::asio::connect(ws.next_layer(), resolver.resolve("127.0.0.1", std::to_string(console->port())));
    const std::string origin = fmt::format("http://127.0.0.1:{}", console->port());  // as the page's own
    ws.set_option(beast::websocket::stream_base::decorator(
        [origin](beast::websocket::request_type& req) { req.set(beast::http::field::origin, origin); }));
    ws.handshake(fmt::format("127.0.0.1:{}", console->port()), "/ws");
    const double cpu0 = cpu_seconds();
    const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
    while (std::chrono::steady_clock::now() < end) {
        beast::flat_buffer buffer;
        ws.read(buffer);
        const double received_ms = utc_ms_now();
        const auto msg = nlohmann::json::parse(beast::buffers_to_string(buffer.data()));
        // From the moment the oldest new sample in this update reached the daemon (its driver
        // handed it over) to its arrival here: the daemon's part of sample-to-screen.
        if (msg["oldest_new_sample_utc_ms"].is_number())
            run.latency_ms.push_back(received_ms - msg["oldest_new_sample_utc_ms"].get<double>());
    }
    run.cpu_percent = 100.0 * (cpu_seconds() - cpu0) / seconds;
    ws.close(beast::websocket::close_code::normal);
    console->stop();
    daemon.stop();
    return run;
}

double percentile(std::vector<double> v, double p) {
    if (v.empty()) return 0;
    std::sort(v.begin(), v.end());
    return v[static_cast<std::size_t>(p * static_cast<double>(v.size() - 1))];
}

}  // namespace

int main(int argc, char** argv) {
    const double seconds = argc > 1 ? std::stod(argv[1]) : 20.0;
    spdlog::set_level(spdlog::level::err);
    const fs::path dir = fs::temp_directory_path() / fmt::format("manikind-bench-console-{}", ::getpid());
    const Run floor = measure(dir / "without", false, seconds);
    const Run with = measure(dir / "with", true, seconds);
    std::printf("console, simulated lab in real time, %.0f s each (cpu = this process: daemon, simulated devices%s)\n", seconds,
                ", and the bench's WebSocket client");
    std::printf("  daemon without the console (floor): %6.2f %% of one core\n", floor.cpu_percent);
    std::printf("  daemon with the console, 1 client:  %6.2f %% of one core  (+%.2f)\n", with.cpu_percent,
                with.cpu_percent - floor.cpu_percent);
    std::printf("  %zu updates carried new samples in %.0f s; oldest new sample, daemon to client: median %.1f ms, p95 %.1f ms, max %.1f ms\n",
                with.latency_ms.size(), seconds, percentile(with.latency_ms, 0.5), percentile(with.latency_ms, 0.95),
                percentile(with.latency_ms, 1.0));
    fs::remove_all(dir);
    return 0;
}
