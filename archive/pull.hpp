#pragma once
// The way back from the archive (docs/archive.md): one lab's campaign, as `manikin archive push`
// sent it, rebuilt inside a recorder database, so that campaign_from_database, the one path from
// samples to analysis columns, reads it as it reads a lab's own file.
#include <cstdint>
#include <string>

#include "store/database.hpp"

namespace manikind::archive {

struct PullResult {
    std::string archive;  // "host:port/dbname", for messages and provenance (no password)
    std::int64_t cases = 0;
    std::int64_t trials = 0;
    std::int64_t events = 0;
    std::int64_t notes = 0;
    std::int64_t samples = 0;
};

// Rebuilds campaign `campaign_name` of lab `lab_id` inside `into`, which must not hold a campaign
// of that name (a fresh file): the campaign, its cases (from the trials' case names and
// conditions, in the order the first replicate ran them), every channel the lab pushed, its
// trials with their UUID, state, reason and times, their events and the lab's "config" events,
// and the trials' samples (one COPY per trial). UserError: status 2 for an unknown lab or
// campaign (the message lists the lab's campaigns) or a bad conninfo, 3 when the server cannot be
// reached or the connection is lost, 4 when it refuses a statement.
PullResult pull_campaign(const std::string& conninfo, const std::string& lab_id, const std::string& campaign_name,
                         recorder::Database& into);

}  // namespace manikind::archive
