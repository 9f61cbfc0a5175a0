#pragma once
// A fuzz target's property check: a property that fails is a finding. libFuzzer reports only the abort, so the
// check names its file and line first.
#include <cstdio>
#include <cstdlib>

namespace imubridge::fuzz {

[[noreturn]] inline void property_fails(const char* file, int line) {
  std::fprintf(stderr, "fuzz: the property at %s:%d fails\n", file, line);
  std::abort();
}

}  // namespace imubridge::fuzz

#define FUZZ_REQUIRE(condition) ((condition) ? void() : ::imubridge::fuzz::property_fails(__FILE__, __LINE__))
