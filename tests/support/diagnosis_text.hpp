#pragma once
// What a failed expectation about diagnose's search prints: the candidates of the step that stopped it, each with why
// it was not taken, so that a failure says which rule refused what.
#include <string>

#include "diagnose/diagnosis.hpp"

namespace imubridge::test {

inline std::string last_candidates(const diagnose::Diagnosis& d) {
  std::string out;
  for (const diagnose::CandidateTrial& t : d.last_candidates)
    out += "\n  " + t.effect + ": " + (t.skipped.empty() ? t.rejected_by : "skipped: " + t.skipped);
  return out;
}

}  // namespace imubridge::test
