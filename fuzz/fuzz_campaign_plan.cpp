// libFuzzer target for campaign files (daemon/campaign_plan.hpp): the input as the TOML
// text of a plan, then the check against the shipped safety limits the daemon makes before it
// starts one. Only UserError may escape, and an accepted plan's names pass the daemon's text rule.
#include <cstdint>
#include <string>

#include "daemon/campaign_plan.hpp"
#include "base/user_error.hpp"
#include "fuzz_check.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    static const auto limits = manikind::config::default_config().safety;
    const std::string text(reinterpret_cast<const char*>(data), size);
    try {
        const auto plan = manikind::parse_campaign_plan(text, "fuzz-campaign.toml");
        // One rule for names and texts (issue 60): a plan the file parser accepts, the daemon's
        // start accepts too (no control character, no '/', bounded, UTF-8).
        FUZZ_CHECK(manikind::plan_text_problem(plan).empty());
        (void)manikind::check_plan_against_limits(plan, limits);
    } catch (const manikind::UserError&) {
    }
    return 0;
}
