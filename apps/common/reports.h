// qpr reports — what the `qpr` subcommands and the viewer report with:
// medians of timing samples, JSON values of summaries, report files. No math
// of the paper lives here.
#pragma once

#include <qpreduce/deform/refine/refine.h>
#include <qpreduce/report.h>

#include <nlohmann/json.hpp>

#include <string>
#include <vector>

namespace qpr {

// The median of `samples`: the middle value, or the mean of the two middle
// values for an even count; 0 for no sample.
double median(std::vector<double> samples);

// The upper median of `samples`: the value at index ⌊count/2⌋ once sorted
// (the middle value, or the upper of the two middle ones); 0 for no sample.
double upper_median(std::vector<double> samples);

// `v` as a JSON number, or null when it is NaN or infinite (JSON has neither).
nlohmann::json finite_or_null(double v);

// A summary's report (qpreduce::Outcome::report()) as a JSON object: the
// one writer of summaries for every app. NaN and infinite reals become
// null, nested reports objects, lists arrays.
nlohmann::json to_json(const qpreduce::Report& report);

// The reports' "refine" object, for `qpr deform --refine` and the viewer's
// --refine: the summary's report and the options it ran with
// (distance_tolerance, tolerance, anderson_window, newton_after).
nlohmann::json refine_json(const qpreduce::deform::RefineSummary& summary,
                           const qpreduce::deform::RefineOptions& options);

// Writes `doc` (indented by 2, then a newline) to `path` through a temporary
// file renamed on success (qpreduce::AtomicFile). Throws qpreduce::FileError
// "<path>: cannot write the <what>: <reason>" when the file cannot be
// written; the earlier file is then untouched.
void write_json(const std::string& path, const nlohmann::json& doc, const std::string& what = "report");

}  // namespace qpr
