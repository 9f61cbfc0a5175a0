// End-to-end latency of `imubridge run`: from a frame's bytes written into a pseudo-terminal to the datagram that
// carries its sample (and the estimate it completes) arriving at a PlotJuggler UDP socket, at 1 kHz, with the
// database recording as in service (recording:1) and without it (recording:0). Target: p99 < 1 ms. The counters
// p50_us, p99_us and max_us are the figures; "Time" is their mean. CPU and memory over a minute: scripts/bench-daemon.
#include <arpa/inet.h>
#include <benchmark/benchmark.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <thread>
#include <vector>

#include "cli/pty.hpp"
#include "daemon/daemon.hpp"
#include "daemon/endpoint.hpp"
#include "sim/frame_encoder.hpp"
#include "sim/scenario.hpp"

namespace imubridge::daemon {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

constexpr double kRateHz = 1000.0;

// A loopback UDP socket standing in for PlotJuggler; a datagram not there within a second is a failure.
struct Receiver {
  Receiver() {
    fd = ::socket(AF_INET, SOCK_DGRAM, 0);
    sockaddr_in address{.sin_family = AF_INET, .sin_port = 0, .sin_addr = {htonl(INADDR_LOOPBACK)}, .sin_zero = {}};
    ::bind(fd, reinterpret_cast<sockaddr*>(&address), sizeof address);
    socklen_t size = sizeof address;
    ::getsockname(fd, reinterpret_cast<sockaddr*>(&address), &size);
    port = ntohs(address.sin_port);
    const timeval timeout{1, 0};
    ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &timeout, sizeof timeout);
  }
  ~Receiver() { ::close(fd); }
  int fd = -1;
  std::uint16_t port = 0;
};

void BM_PtyToOutputLatency(benchmark::State& state) {
  const fs::path dir = fs::temp_directory_path() / ("imubridge_latency_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  // The paper's vehicle, so the estimator does all of its work (compensation and the drag inversion).
  sim::SimConfig flight = sim::make_scenario("paper", 1, 30.0);
  flight.imu.rate_hz = kRateHz;
  std::vector<std::vector<std::uint8_t>> frames;
  sim::FrameEncoder encoder(protocol::WireFormat::imubridge);
  sim::simulate(flight, [&](const sim::SimSample& s) { encoder.encode(s, frames.emplace_back()); });
  estimator::ModelParams params;
  params.full.lever_arm = {sim::kPaperR * std::cos(sim::kPaperBeta), 0.0, -sim::kPaperR * std::sin(sim::kPaperBeta)};
  params.full.drag_quadratic = {sim::kPaperMu, sim::kPaperMu};
  std::ofstream(dir / "params.json") << nlohmann::json(params).dump();

  Receiver receiver;
  cli::PtyPair pty(dir / "tty");
  Config config;
  config.log_level = "off";  // the "not recording" line of recording:0 is expected
  config.store.path = dir / "latency.db";
  const bool recording = state.range(0) != 0;
  config.store.min_free_bytes = recording ? 0 : ~0ull;  // no disk has that much free: the daemon does not record
  config.params = dir / "params.json";
  config.outputs.plotjuggler = parse_endpoint("udp://127.0.0.1:" + std::to_string(receiver.port));
  LinkConfig link;
  link.name = "imu";
  link.device.path = dir / "tty";
  config.links.push_back(link);
  configure_logging(config);
  Daemon daemon(config);
  std::thread loop([&] { daemon.run(); });

  std::vector<double> latencies_us;
  char datagram[2048];
  std::size_t next = 0;
  auto due = Clock::now() + std::chrono::milliseconds(200);  // the daemon opens the port meanwhile
  for (auto _ : state) {
    std::this_thread::sleep_until(due);
    due += std::chrono::microseconds(static_cast<int>(1e6 / kRateHz));
    const auto written = Clock::now();
    pty.write(frames[next % frames.size()]);
    const ssize_t n = ::recv(receiver.fd, datagram, sizeof datagram, 0);
    const auto arrived = Clock::now();
    if (n <= 0) {
      state.SkipWithError("no datagram within 1 s");
      break;
    }
    const double us = std::chrono::duration<double, std::micro>(arrived - written).count();
    latencies_us.push_back(us);
    state.SetIterationTime(us * 1e-6);
    ++next;
  }
  daemon.stop();
  loop.join();
  fs::remove_all(dir);

  if (latencies_us.empty()) return;
  std::sort(latencies_us.begin(), latencies_us.end());
  const auto percentile = [&](double p) {
    return latencies_us[std::min(latencies_us.size() - 1, static_cast<std::size_t>(p * latencies_us.size()))];
  };
  state.counters["p50_us"] = percentile(0.50);
  state.counters["p99_us"] = percentile(0.99);
  state.counters["max_us"] = latencies_us.back();
  state.counters["frames"] = static_cast<double>(latencies_us.size());
}
// 10 s of frames at 1 kHz, enough for 50 commits to show in the tail; without recording, for the store's share.
BENCHMARK(BM_PtyToOutputLatency)
    ->ArgName("recording")
    ->Arg(1)
    ->Arg(0)
    ->Iterations(10000)
    ->UseManualTime()
    ->Unit(benchmark::kMicrosecond);

}  // namespace
}  // namespace imubridge::daemon
