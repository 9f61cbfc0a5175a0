#pragma once
// The one way work is spread over cores here: the caller hands out its own tasks (an atomic counter the workers take
// from as they come free), so the numbers come out the same however the tasks were shared.
#include <algorithm>
#include <cstddef>
#include <thread>
#include <vector>

namespace imubridge::estimator {

// The machine's cores, at least 1 (hardware_concurrency may not know).
inline unsigned cores() { return std::max(1u, std::thread::hardware_concurrency()); }

// Runs work(w) for every worker w in [0, workers) at once, worker 0 on the calling thread (so at least one runs), and
// returns when every one has returned.
template <typename Work>
void on_threads(std::size_t workers, Work&& work) {
  std::vector<std::thread> helpers;
  for (std::size_t w = 1; w < workers; ++w) helpers.emplace_back([&work, w] { work(w); });
  work(std::size_t{0});
  for (std::thread& helper : helpers) helper.join();
}

}  // namespace imubridge::estimator
