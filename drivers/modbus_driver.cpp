#include "drivers/modbus_driver.hpp"
#include "base/guarded.hpp"

#include <fmt/format.h>

#include <cerrno>
#include <cmath>
#include <stdexcept>

namespace manikind::drivers {

namespace mr = protocol::modbus_registers;

namespace mb = protocol::modbus_blocks;

namespace {

// A timeout, a broken link or a garbled answer leaves unknown bytes in flight: the connection is
// dropped and opened again from clean.
bool link_lost(int err) {
    return err == ETIMEDOUT || err == ECONNRESET || err == EPIPE || err == EBADF || err == ECONNREFUSED || err == EMBBADDATA ||
           err == EMBBADEXC || err == EMBBADCRC || err == EIO;
}

mb::PointRegisters point_registers(const ModbusPoint& p) {
    return {p.unit_id, p.input_register, p.spec.address, mr::register_count(p.spec.type)};
}

}  // namespace

ModbusDriver::ModbusDriver(ModbusOptions options, const Clock& clock, SampleSink sink)
    : options_(std::move(options)), clock_(clock), sink_(std::move(sink)) {
    std::vector<mb::PointRegisters> regs;
    std::vector<std::size_t> polled;
    for (std::size_t i = 0; i < options_.points.size(); ++i) {
        const auto& p = options_.points[i];
        if (!p.poll) continue;
        regs.push_back(point_registers(p));
        polled.push_back(i);
    }
    blocks_ = mb::plan_read_blocks(regs, mb::kMaxReadRegisters, options_.max_gap_registers);
    for (auto& b : blocks_)
        for (auto& i : b.points) i = polled[i];  // indices into options_.points
    status_.name = options_.device_name;
    status_.transport = options_.serial_path.empty()
                            ? fmt::format("modbus-tcp {}:{}", options_.host, options_.port)
                            : fmt::format("modbus-rtu {} {} baud", options_.serial_path, options_.baud);
}

ModbusDriver::~ModbusDriver() { stop(); }

void ModbusDriver::start() {
    std::lock_guard lk(io_lock_);
    ensure_connected(clock_.mono_ns());
}

void ModbusDriver::stop() {
    {
        std::lock_guard lk(worker_lock_);
        worker_stop_ = true;
    }
    worker_cv_.notify_all();
    if (worker_.joinable()) worker_.join();
    std::lock_guard lk(io_lock_);
    disconnect();
}

void ModbusDriver::disconnect() {
    tcp_.close();
    if (ctx_) {
        modbus_close(ctx_);
        modbus_free(ctx_);
        ctx_ = nullptr;
    }
    std::lock_guard lk(status_lock_);
    status_.connected = false;
}

bool ModbusDriver::ensure_connected(std::int64_t now_ns) {
    if (is_open()) return true;
    if (!backoff_.due(now_ns)) return false;
    if (tcp()) {
        if (const std::string why = tcp_.connect(options_.host, options_.port, options_.response_timeout_s); !why.empty()) {
            record_error(fmt::format("connect {}: {}", status_.transport, why));
            backoff_.failed(now_ns);
            return false;
        }
    } else {
        modbus_t* ctx = modbus_new_rtu(options_.serial_path.c_str(), options_.baud, 'N', 8, 1);
        if (!ctx) {
            record_error(std::string("modbus_new_rtu: ") + modbus_strerror(errno));
            backoff_.failed(now_ns);
            return false;
        }
        const double t = options_.response_timeout_s;
        const auto sec = static_cast<std::uint32_t>(t);
        modbus_set_response_timeout(ctx, sec, static_cast<std::uint32_t>((t - sec) * 1e6));
        if (modbus_connect(ctx) == -1) {
            record_error(fmt::format("connect {}: {}", status_.transport, modbus_strerror(errno)));
            modbus_free(ctx);
            backoff_.failed(now_ns);
            return false;
        }
        ctx_ = ctx;
    }
    // The backoff is reset by an answer, not by the connect: a silent device (a gateway that
    // accepts TCP, a dead RTU slave) would otherwise cost a full response timeout per register
    // every poll, and on the virtual clock stall the whole lab (issue 17).
    std::lock_guard lk(status_lock_);
    if (ever_connected_) ++status_.reconnects;
    ever_connected_ = true;
    status_.connected = true;
    if (status_.last_good_mono_ns < 0) status_.last_good_mono_ns = now_ns;
    return true;
}

void ModbusDriver::record_error(const std::string& what) {
    std::lock_guard lk(status_lock_);
    ++status_.comm_errors;
    status_.last_error = what;
}

const ModbusPoint* ModbusDriver::find(const std::string& channel) const {
    for (const auto& p : options_.points)
        if (p.channel == channel) return &p;
    return nullptr;
}

// Caller holds io_lock_. Counts the error by kind, and drops the connection where link_lost says.
void ModbusDriver::count_error(int err, const std::string& what) {
    {
        std::lock_guard lk(status_lock_);
        status_.last_error = fmt::format("{}: {}", what, modbus_strerror(err));
        if (err == ETIMEDOUT) {
            ++status_.timeouts;
        } else if (err > MODBUS_ENOBASE && err < MODBUS_ENOBASE + 16) {
            ++status_.exceptions;  // an exception response: the link itself is fine
        } else if (err == EMBBADCRC) {
            ++status_.checksum_errors;
        } else {
            ++status_.comm_errors;
        }
    }
    if (link_lost(err)) disconnect();
}

double ModbusDriver::decode_point(const ModbusPoint& p, std::span<const std::uint16_t> words, Quality& quality) const {
    double value = mr::decode(p.spec, words);
    if (p.scaling) value = p.scaling->to_value(value);
    quality = (!std::isfinite(value) || value < p.valid_min || value > p.valid_max) ? Quality::out_of_range
                                                                                     : Quality::good;
    return value;
}

// Caller holds io_lock_ and the connection is open.
std::optional<double> ModbusDriver::read_point(const ModbusPoint& p, Quality& quality) {
    const mb::ReadBlock one{p.unit_id, p.input_register, p.spec.address, mr::register_count(p.spec.type), {0}};
    std::vector<BlockRead> got;
    read_blocks(std::span<const mb::ReadBlock>(&one, 1), got);
    if (got[0].err != 0) {
        quality = Quality::comm_error;
        count_error(got[0].err, fmt::format("{} (unit {}, register {}){}", p.channel, p.unit_id, p.spec.address, got[0].why));
        return std::nullopt;
    }
    return decode_point(p, got[0].words, quality);
}

// Caller holds io_lock_ and the connection is open.
void ModbusDriver::read_blocks(std::span<const mb::ReadBlock> blocks, std::vector<BlockRead>& out) {
    out.assign(blocks.size(), BlockRead{});
    if (tcp()) {
        namespace mtcp = protocol::modbus_tcp;
        std::vector<ModbusTcpClient::Call> calls(blocks.size());
        for (std::size_t i = 0; i < blocks.size(); ++i) {
            auto& q = calls[i].request;
            q.unit = static_cast<std::uint8_t>(blocks[i].unit_id);
            q.function = blocks[i].input_register ? mtcp::kReadInput : mtcp::kReadHolding;
            q.address = static_cast<std::uint16_t>(blocks[i].start);
            q.count = static_cast<std::uint16_t>(blocks[i].count);
        }
        tcp_.transact(calls);
        for (std::size_t i = 0; i < blocks.size(); ++i) {
            out[i].err = calls[i].err;
            out[i].words = std::move(calls[i].words);
            if (!calls[i].why.empty()) out[i].why = ": " + calls[i].why;
        }
        return;
    }
    for (std::size_t i = 0; i < blocks.size(); ++i) {
        const auto& b = blocks[i];
        if (!ctx_) {  // the link failed on an earlier request of this poll
            out[i].err = ENOTCONN;
            continue;
        }
        out[i].words.assign(static_cast<std::size_t>(b.count), 0);
        modbus_set_slave(ctx_, b.unit_id);
        const int rc = b.input_register ? modbus_read_input_registers(ctx_, b.start, b.count, out[i].words.data())
                                        : modbus_read_registers(ctx_, b.start, b.count, out[i].words.data());
        if (rc == b.count) continue;
        out[i].err = errno;
        if (link_lost(out[i].err)) {
            for (std::size_t k = i + 1; k < blocks.size(); ++k) out[k].err = ENOTCONN;  // count_error drops the link
            return;
        }
    }
}

void ModbusDriver::poll() {
    // Outside the I/O lock: a sink may call back into write() (safety actions, setpoints).
    for (const auto& s : read_all()) sink_(s);
}

std::vector<Sample> ModbusDriver::read_all() {
    std::vector<Sample> out;
    {
        std::lock_guard lk(io_lock_);
        const std::int64_t now = clock_.mono_ns();
        const std::int64_t utc = clock_.utc_ns();
        bool any_good = false;
        // Per point, in the configured order: value and quality (comm_error until read).
        std::vector<std::optional<double>> values(options_.points.size());
        std::vector<Quality> qualities(options_.points.size(), Quality::comm_error);
        std::vector<BlockRead> got;
        const std::size_t in_flight = tcp() ? static_cast<std::size_t>(std::max(1, options_.requests_in_flight)) : 1;
        for (std::size_t bi = 0; bi < blocks_.size();) {
            if (!ensure_connected(now)) {
                ++bi;
                continue;
            }
            const std::size_t n = std::min(in_flight, blocks_.size() - bi);
            read_blocks(std::span<const mb::ReadBlock>(blocks_).subspan(bi, n), got);
            std::size_t next = bi + n;
            for (std::size_t k = 0; k < n; ++k) {
                const mb::ReadBlock& b = blocks_[bi + k];
                const int err = got[k].err;
                if (err == ENOTCONN) continue;  // lost with the link, whose failure is counted once
                if (err == EMBXILADD && b.points.size() > 1) {
                    // The device refuses this range. A block bridged across unused registers is
                    // split into its contiguous runs (the device may lack the registers between);
                    // a contiguous one is read point by point (it allows one register a request).
                    std::vector<mb::PointRegisters> regs;
                    for (const std::size_t i : b.points) regs.push_back(point_registers(options_.points[i]));
                    auto smaller = mb::plan_read_blocks(regs, mb::kMaxReadRegisters, 0);
                    const bool bridged = smaller.size() > 1;
                    if (!bridged) smaller = mb::plan_read_blocks(regs, 0, 0);  // at most 0 registers: one point a request
                    for (auto& sb : smaller)
                        for (auto& i : sb.points) i = b.points[i];  // back to indices into options_.points
                    {
                        std::lock_guard sl(status_lock_);
                        ++status_.exceptions;
                        status_.last_error = fmt::format("registers {}..{} (unit {}) refused as one request (illegal data "
                                                         "address); reading {} from now on",
                                                         b.start, b.start + b.count - 1, b.unit_id,
                                                         bridged ? "their contiguous runs" : "them one at a time");
                    }
                    const auto at = blocks_.begin() + static_cast<std::ptrdiff_t>(bi + k);
                    blocks_.erase(at);
                    blocks_.insert(blocks_.begin() + static_cast<std::ptrdiff_t>(bi + k), smaller.begin(), smaller.end());
                    // Read the smaller blocks now; the replies after this one in the batch are
                    // dropped and their blocks read again with them.
                    next = bi + k;
                    break;
                }
                if (err != 0) {
                    const auto& first = options_.points[b.points.front()];
                    count_error(err, b.points.size() == 1
                                         ? fmt::format("{} (unit {}, register {}){}", first.channel, b.unit_id, b.start, got[k].why)
                                         : fmt::format("{} and {} more (unit {}, registers {}..{}){}", first.channel,
                                                       b.points.size() - 1, b.unit_id, b.start, b.start + b.count - 1,
                                                       got[k].why));
                    if (!is_open()) backoff_.failed(now);  // dropped after a timeout: the next try waits
                    continue;
                }
                {
                    std::lock_guard sl(status_lock_);
                    ++status_.frames;
                }
                for (const std::size_t i : b.points) {
                    const auto& p = options_.points[i];
                    const auto offset = static_cast<std::size_t>(p.spec.address - b.start);
                    Quality q = Quality::good;
                    values[i] = decode_point(p,
                                             std::span<const std::uint16_t>(got[k].words)
                                                 .subspan(offset, static_cast<std::size_t>(mr::register_count(p.spec.type))),
                                             q);
                    qualities[i] = q;
                    any_good = true;
                    if (q == Quality::good) {
                        std::lock_guard sl(status_lock_);
                        ++status_.samples;
                    }
                }
            }
            bi = next;
        }
        for (std::size_t i = 0; i < options_.points.size(); ++i) {
            const auto& p = options_.points[i];
            if (!p.poll) continue;
            out.push_back(Sample{options_.device_name, p.channel, values[i].value_or(std::nan("")),
                                 values[i] ? qualities[i] : Quality::comm_error, now, utc});
        }
        if (any_good) backoff_.reset();
        std::lock_guard sl(status_lock_);
        if (any_good) {
            status_.last_good_mono_ns = now;
            status_.stale = false;
        }
    }
    return out;
}

void ModbusDriver::start_worker() {
    worker_stop_ = false;
    worker_ = std::thread([this] {
        run_guarded("Modbus poll", [this] {
            std::unique_lock lk(worker_lock_);
            while (!worker_stop_) {
                lk.unlock();
                poll();
                lk.lock();
                worker_cv_.wait_for(lk, std::chrono::duration<double>(options_.poll_period_s), [this] { return worker_stop_; });
            }
        });
    });
}

void ModbusDriver::check(std::int64_t now_mono_ns) {
    std::lock_guard lk(status_lock_);
    const auto limit_ns = static_cast<std::int64_t>(3.0 * options_.poll_period_s * 1e9) + 1'000'000'000;
    if (status_.last_good_mono_ns >= 0 && now_mono_ns - status_.last_good_mono_ns > limit_ns) status_.stale = true;
}

DriverStatus ModbusDriver::status() const {
    std::lock_guard lk(status_lock_);
    return status_;
}

std::string ModbusDriver::write(const std::string& channel, double value) {
    const ModbusPoint* p = find(channel);
    if (!p) return "no register named " + channel + " on " + options_.device_name;
    std::vector<std::uint16_t> words;
    try {
        words = mr::encode(p->spec, value);
    } catch (const std::exception& e) {
        return e.what();
    }
    std::lock_guard lk(io_lock_);
    if (!ensure_connected(clock_.mono_ns())) return options_.device_name + " is not connected: " + status().last_error;
    int err = 0;
    std::string detail;
    if (tcp()) {
        namespace mtcp = protocol::modbus_tcp;
        ModbusTcpClient::Call call;
        call.request.unit = static_cast<std::uint8_t>(p->unit_id);
        call.request.function = words.size() == 1 ? mtcp::kWriteSingle : mtcp::kWriteMultiple;
        call.request.address = static_cast<std::uint16_t>(p->spec.address);
        call.request.count = static_cast<std::uint16_t>(words.size());
        call.request.values = words;
        tcp_.transact(std::span<ModbusTcpClient::Call>(&call, 1));
        err = call.err;
        if (!call.why.empty()) detail = " (" + call.why + ")";
    } else {
        modbus_set_slave(ctx_, p->unit_id);
        const int rc = words.size() == 1 ? modbus_write_register(ctx_, p->spec.address, words[0])
                                         : modbus_write_registers(ctx_, p->spec.address, static_cast<int>(words.size()),
                                                                  words.data());
        err = rc == -1 ? errno : 0;
    }
    if (err != 0) {
        const std::string why = fmt::format("write {} = {}: {}{}", channel, value, modbus_strerror(err), detail);
        record_error(why);
        if (err == ETIMEDOUT || err == ECONNRESET || err == EPIPE || err == EMBBADDATA || !is_open()) disconnect();
        return why;
    }
    return {};
}

std::optional<double> ModbusDriver::read(const std::string& channel) {
    const ModbusPoint* p = find(channel);
    if (!p) return std::nullopt;
    std::lock_guard lk(io_lock_);
    if (!ensure_connected(clock_.mono_ns())) return std::nullopt;
    Quality q = Quality::good;
    return read_point(*p, q);
}

}  // namespace manikind::drivers
