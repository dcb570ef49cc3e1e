#include "protocol/modbus_blocks.hpp"

#include <algorithm>
#include <numeric>
#include <tuple>

namespace manikind::protocol::modbus_blocks {

std::vector<ReadBlock> plan_read_blocks(std::span<const PointRegisters> points, int max_registers, int max_gap) {
    std::vector<std::size_t> order(points.size());
    std::iota(order.begin(), order.end(), std::size_t{0});
    std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
        const auto& pa = points[a];
        const auto& pb = points[b];
        return std::tie(pa.unit_id, pa.input_register, pa.address) < std::tie(pb.unit_id, pb.input_register, pb.address);
    });
    std::vector<ReadBlock> blocks;
    for (const std::size_t i : order) {
        const auto& p = points[i];
        const int end = p.address + std::max(1, p.count);  // one past the point's last register
        if (!blocks.empty()) {
            auto& b = blocks.back();
            const int block_end = b.start + b.count;
            const bool same_request = b.unit_id == p.unit_id && b.input_register == p.input_register;
            if (same_request && p.address <= block_end + max_gap && std::max(end, block_end) - b.start <= max_registers) {
                b.count = std::max(end, block_end) - b.start;
                b.points.push_back(i);
                continue;
            }
        }
        blocks.push_back({p.unit_id, p.input_register, p.address, end - p.address, {i}});
    }
    return blocks;
}

}  // namespace manikind::protocol::modbus_blocks
