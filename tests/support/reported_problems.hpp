#pragma once
// The problems an import reports through its options' on_problem (importers/import_problem.hpp), kept for a test to
// look at.
#include <cstdint>
#include <map>
#include <string>
#include <string_view>
#include <vector>

#include "importers/import_problem.hpp"

namespace imubridge::test {

struct ReportedProblems {
  std::vector<importers::ImportProblem> all;

  importers::ProblemCallback callback() {
    return [this](const importers::ImportProblem& p) { all.push_back(p); };
  }
  // The problems of `kind` whose `what` holds `what`.
  std::vector<importers::ImportProblem> of(importers::ProblemKind kind, std::string_view what = "") const {
    std::vector<importers::ImportProblem> out;
    for (const auto& p : all) {
      if (p.kind == kind && p.what.find(what) != std::string::npos) out.push_back(p);
    }
    return out;
  }
  // Their counts by reason.
  std::map<std::string, std::uint64_t> counts(importers::ProblemKind kind, std::string_view what = "") const {
    std::map<std::string, std::uint64_t> out;
    for (const auto& p : of(kind, what)) out[p.why] += p.count;
    return out;
  }
  // Where they are, by reason.
  std::map<std::string, std::string> places(importers::ProblemKind kind, std::string_view what = "") const {
    std::map<std::string, std::string> out;
    for (const auto& p : of(kind, what)) out[p.why] = p.where.value_or("");
    return out;
  }
  std::uint64_t total(importers::ProblemKind kind, std::string_view what = "") const {
    std::uint64_t n = 0;
    for (const auto& p : of(kind, what)) n += p.count;
    return n;
  }
};

}  // namespace imubridge::test
