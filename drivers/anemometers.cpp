#include "drivers/anemometers.hpp"

#include <cmath>

namespace manikind::drivers {

void WindSonicDriver::on_bytes(const std::uint8_t* data, std::size_t n) {
    using Event = protocol::windsonic::Parser::Event;
    for (std::size_t i = 0; i < n; ++i) {
        const Event ev = parser_.feed(data[i]);
        if (ev == Event::none) continue;
        if (ev == Event::checksum_error || ev == Event::malformed) {
            std::lock_guard lk(lock_);
            // "last error" says what the counters count (issue 35: errors 1 beside an empty one).
            if (ev == Event::checksum_error) {
                ++status_.checksum_errors;
                status_.last_error = "a line whose checksum does not match (garbled in transit)";
            } else {
                ++status_.malformed;
                status_.last_error = "a malformed line (not the WindSonic's output format)";
            }
            continue;
        }
        const auto& r = parser_.reading();
        const bool ok = protocol::windsonic::status_ok(r.status);
        {
            std::lock_guard lk(lock_);
            note_good_frame();
            if (!ok) {
                ++status_.device_faults;
                status_.last_error = std::string("status ") + protocol::windsonic::status_text(r.status);
            }
        }
        last_ = r;
        const Quality q = ok ? Quality::good : Quality::out_of_range;
        emit("air_speed_m_s", r.speed_m_s(), q);
        if (r.direction_deg) emit("air_direction_deg", *r.direction_deg, q);
    }
}

void WindSonicDriver::emit_degraded(Quality quality) {
    emit("air_speed_m_s", last_ ? last_->speed_m_s() : std::nan(""), quality);
}

void Csat3bDriver::on_bytes(const std::uint8_t* data, std::size_t n) {
    using Event = protocol::csat3b::Parser::Event;
    for (std::size_t i = 0; i < n; ++i) {
        const Event ev = parser_.feed(data[i]);
        if (ev == Event::none) continue;
        if (ev == Event::signature_error || ev == Event::malformed) {
            std::lock_guard lk(lock_);
            if (ev == Event::signature_error) {
                ++status_.checksum_errors;
                status_.last_error = "a record whose signature does not match (garbled in transit)";
            } else {
                ++status_.malformed;
                status_.last_error = "a malformed record (not the CSAT3B's output format)";
            }
            continue;
        }
        const auto& r = parser_.record();
        const bool ok = r.diag == 0 && std::isfinite(r.ux_m_s);
        {
            std::lock_guard lk(lock_);
            note_good_frame();
            if (!ok) {
                ++status_.device_faults;
                status_.last_error = "diagnostic word: " + protocol::csat3b::diag_text(r.diag);
            }
        }
        last_ = r;
        const Quality q = ok ? Quality::good : Quality::out_of_range;
        emit("air_speed_m_s", r.speed_m_s(), q);
        emit("ux_m_s", r.ux_m_s, q);
        emit("uy_m_s", r.uy_m_s, q);
        emit("uz_m_s", r.uz_m_s, q);
        emit("sonic_temp_c", r.sonic_temp_c, q);
    }
}

void Csat3bDriver::emit_degraded(Quality quality) {
    emit("air_speed_m_s", last_ ? last_->speed_m_s() : std::nan(""), quality);
}

}  // namespace manikind::drivers
