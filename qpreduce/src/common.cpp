#include "qpreduce/common.h"

namespace qpreduce {

const char* to_string(Status status) {
  switch (status) {
    case Status::NotRun: return "not-run";
    case Status::Success: return "success";
    case Status::ConstraintsLeastSquares: return "constraints-least-squares";
    case Status::RankDeficientC: return "rank-deficient-C";
    case Status::DependentCD: return "dependent-C-D";
    case Status::IndefiniteH: return "indefinite-H";
    case Status::SingularKKT: return "singular-KKT";
    case Status::Unbounded: return "unbounded";
    case Status::NumericalFailure: return "numerical-failure";
  }
  return "unknown";
}

Report Outcome::report() const {
  Report r;
  r.add("status", to_string(status)).add("message", message);
  add_details(&r);
  return r;
}

std::string Outcome::full_report() const { return report().text(); }

void Outcome::add_details(Report*) const {}

std::string Outcome::brief_report() const {
  return message.empty() ? std::string(to_string(status)) : std::string(to_string(status)) + ": " + message;
}

}  // namespace qpreduce
