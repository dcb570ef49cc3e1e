#pragma once
// The two sonic anemometers. WindSonic (Gill, 2-D, RS-232, ASCII with an XOR checksum):
// channel air_speed_m_s (+ air_direction_deg). CSAT3B (Campbell Scientific, 3-D, RS-485/USB,
// ASCII with a signature): air_speed_m_s (3-D magnitude), ux/uy/uz, sonic_temp_c. A non-zero
// WindSonic status code or CSAT3B diagnostic word flags the sample out-of-range and is counted
// as a device fault; checksum failures are counted and the frame dropped.
#include <optional>

#include "drivers/serial_line_driver.hpp"
#include "protocol/csat3b.hpp"
#include "protocol/windsonic.hpp"

namespace manikind::drivers {

class WindSonicDriver final : public SerialLineDriver {
public:
    using SerialLineDriver::SerialLineDriver;
    // Polled mode (manual section 9): the host sends the node letter and the unit answers one frame.
    void poll(char node = 'Q') { send(std::string(1, node)); }
    const protocol::windsonic::Parser::Counters& codec_counters() const { return parser_.counters(); }

private:
    void on_bytes(const std::uint8_t* data, std::size_t n) override;
    void emit_degraded(Quality quality) override;
    protocol::windsonic::Parser parser_;
    std::optional<protocol::windsonic::Reading> last_;
};

class Csat3bDriver final : public SerialLineDriver {
public:
    using SerialLineDriver::SerialLineDriver;
    const protocol::csat3b::Parser::Counters& codec_counters() const { return parser_.counters(); }

private:
    void on_bytes(const std::uint8_t* data, std::size_t n) override;
    void emit_degraded(Quality quality) override;
    protocol::csat3b::Parser parser_;
    std::optional<protocol::csat3b::Record> last_;
};

}  // namespace manikind::drivers
