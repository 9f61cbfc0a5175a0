// What the MQTT output costs the recording's thread: MqttSink::on_sample for a 200 Hz link whose every sample
// completes an estimate, with the default caps (samples at 50 Hz, every estimate: 1.25 messages per sample). With a
// mosquitto broker on the loopback that this benchmark starts (broker:1), the sink's threads publish meanwhile; with
// none (broker:0) the outbox stays full and each message pushes the oldest out. "Time" is per sample.
#include <benchmark/benchmark.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <fstream>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "bench/scratch_dir.hpp"
#include "daemon/live_sinks.hpp"
#include "daemon/mqtt_output.hpp"
#include "daemon/outputs.hpp"
#include "tests/support/loopback_port.hpp"

namespace imubridge::daemon {
namespace {

// `mosquitto -c` on 127.0.0.1:port, anonymous, its log discarded.
class Broker {
 public:
  Broker(const std::filesystem::path& dir, std::uint16_t port) {
    const auto conf = dir / "mosquitto.conf";
    std::ofstream(conf) << "listener " << port << " 127.0.0.1\nallow_anonymous true\npersistence false\n"
                        << "log_dest none\n";
    pid_ = ::fork();
    if (pid_ == 0) {
      ::execl("/usr/sbin/mosquitto", "mosquitto", "-c", conf.c_str(), nullptr);
      ::_exit(127);
    }
  }
  ~Broker() {
    ::kill(pid_, SIGTERM);
    ::waitpid(pid_, nullptr, 0);
  }

 private:
  pid_t pid_ = -1;
};

void BM_MqttOnSample(benchmark::State& state) {
  const bool with_broker = state.range(0) != 0;
  bench::ScratchDir dir;
  const std::uint16_t port = test::free_loopback_port();
  std::unique_ptr<Broker> broker;
  if (with_broker) broker = std::make_unique<Broker>(dir.database().parent_path(), port);

  boost::asio::io_context io;  // not run: the sink's log lines and timers wait, as they cost the loop nothing here
  OutputsConfig config;
  Outputs outputs(io, config);
  const LiveContext context{
      .io = io, .outputs = outputs, .config = config, .record_event = [](auto, auto, auto, auto) {}};
  MqttConfig mqtt;
  mqtt.url = "mqtt://127.0.0.1:" + std::to_string(port);
  mqtt.host = "127.0.0.1";
  mqtt.port = port;
  mqtt.station = "bench";
  mqtt.reconnect_max = std::chrono::seconds(1);
  mqtt.client_id = "imubridge-bench";
  LiveLink link;
  link.name = "imu";
  MqttSink sink(mqtt, {link}, context);
  if (with_broker) {
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
    while (!sink.counters().at("connected").get<bool>()) {
      if (std::chrono::steady_clock::now() > deadline) throw std::runtime_error("no broker");
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
  }

  protocol::Sample sample{.link_id = 1, .accel = {0.1, -0.2, -9.8}, .gyro = {0.01, 0.02, 0.3}};
  store::Estimate estimate{.link_id = 1, .fx = 0.5, .fy = -0.25, .vx = 1.5, .vy = -0.5, .var_vx = 0.01, .var_vy = 0.02};
  std::int64_t mono_ns = 1'000'000'000;
  for (auto _ : state) {
    ++sample.seq;
    sample.device_time_us += 5000;  // 200 Hz
    mono_ns += 5'000'000;
    estimate.seq = sample.seq - 2;
    sink.on_sample(0, sample, std::span(&estimate, 1), mono_ns);
  }
  const auto counters = sink.counters();
  state.counters["published"] = counters.at("published").get<double>();
  state.counters["dropped"] = counters.at("dropped").get<double>();
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_MqttOnSample)->ArgName("broker")->Arg(0)->Arg(1);

}  // namespace
}  // namespace imubridge::daemon
