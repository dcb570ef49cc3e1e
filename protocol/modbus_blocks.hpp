#pragma once
// Which registers to read in one Modbus request. A datalogger's inputs sit at consecutive
// addresses; reading them one request each costs a round trip per point (on RS-485 at 9600
// baud about 20 ms: 12 points would eat a quarter of a 1-s poll). As EPICS' modbus module
// does, contiguous registers of one unit and function go in one request, up to the protocol's
// 125 registers (Modbus Application Protocol v1.1b3, §6.3/6.4: 1..125 for FC 03 and 04).
// Pure: no I/O.
#include <cstddef>
#include <span>
#include <vector>

namespace manikind::protocol::modbus_blocks {

inline constexpr int kMaxReadRegisters = 125;

struct PointRegisters {
    int unit_id = 1;
    bool input_register = false;  // FC 04, else FC 03
    int address = 0;              // first register
    int count = 1;                // registers the point's type spans
};

struct ReadBlock {
    int unit_id = 1;
    bool input_register = false;
    int start = 0;
    int count = 0;
    std::vector<std::size_t> points;  // indices into the planned points, by address
};

// Fewest requests covering every point: same unit and function, each register after the
// previous point's last within `max_gap` registers (0: contiguous or overlapping only, since a
// device may answer "illegal data address" for a hole), at most `max_registers` per request.
// Blocks come ordered by unit, function, then address. `max_registers` 0 gives every point its
// own request, whatever it spans (a device that allows one value a request).
std::vector<ReadBlock> plan_read_blocks(std::span<const PointRegisters> points, int max_registers = kMaxReadRegisters,
                                        int max_gap = 0);

}  // namespace manikind::protocol::modbus_blocks
