#pragma once
// The printable campaign (or trial) report a lab hands a client (issue 35; docs/cli.md, "manikin
// report"): conditions, each trial's stage times and steady-state verdict, whole-body fluxes with
// their 95 % intervals and the figure (analysis/plot.hpp), the lab notebook and the alarms.
// Plain HTML with inline SVG, no script and nothing loaded from elsewhere; one trial per printed
// page after the campaign's summary. Pure: the caller (cli/) reads the database.
#include <cstdint>
#include <string>
#include <vector>

#include "analysis/analyze.hpp"
#include "analysis/recording.hpp"

namespace manikind::analysis {

struct ReportEvent {
    std::int64_t utc_ns = 0;
    std::string severity;  // info, warn, error
    std::string kind;      // stage, gap, safety, ...
    std::string message;
};

struct ReportTrial {
    std::string id;                  // the exported trial id (c01-r1)
    std::int64_t database_id = 0;
    std::string state, reason;       // done, aborted, interrupted, failed, or running
    std::vector<ReportEvent> stages; // kind "stage" events, in order
    std::vector<ReportEvent> alarms; // warn and error events
};

struct LabReportInput {
    std::string lab_name;
    std::string generated_utc;       // ISO 8601
    std::string only_trial;          // empty: the whole campaign
    const Campaign* campaign = nullptr;
    const CampaignResult* result = nullptr;
    std::vector<ReportTrial> trials; // every trial the database holds, in order
    std::vector<ReportEvent> campaign_alarms;  // warn/error events of no trial within the campaign's time
};

std::string lab_report_html(const LabReportInput& in);

}  // namespace manikind::analysis
