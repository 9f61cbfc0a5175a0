// The configuration of `imubridge run`: TOML keys to Config, one-line errors naming the key, the --link shorthand,
// and the snapshot a session keeps.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "daemon/config_file.hpp"
#include "daemon/link_spec.hpp"
#include "pipeline/session_config.hpp"

namespace imubridge::daemon {
namespace {

using namespace std::chrono_literals;

// The one-line message parse_config() throws, or "" when it accepts the text.
std::string error_of(const std::string& toml) {
  try {
    parse_config(toml, "test.toml");
    return "";
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
}

const std::string kLink = "[[link]]\nname = \"imu\"\ndevice = \"/dev/ttyUSB0\"\n";

TEST(ConfigFile, EveryKeyReachesItsField) {
  const Config c = parse_config(R"(
log_level = "debug"
log_file = "/var/log/imubridge.log"
stats_interval_s = 5
params = "p.json"
[store]
path = "/data/flights.db"
commit_interval_ms = 100
max_size_mib = 1.5
min_free_mib = 10
on_full = "stop"
[outputs]
plotjuggler = "udp://127.0.0.1:9870"
line_streams = ["tcp-listen://127.0.0.1:9871", "unix:///tmp/lines.sock"]
decimation = 4
[[link]]
name = "radio"
usb = { vid = 0x0403, pid = 0x6015, serial = "DN02ABCD" }
protocol = "xbee-escaped"
baud = 57600
reconnect_min_ms = 50
reconnect_max_ms = 800
bridge = ["udp://127.0.0.1:14550"]
[link.feedback]
rate_hz = 5
xbee_destination64 = "0013A20040A1B2C3"
[link.calibration.gyro]
sign = [1, -1, -1]
[[link]]
name = "fc"
device = "/dev/ttyACM0"
protocol = "mavlink"
)",
                                "test.toml");
  EXPECT_EQ(c.log_level, "debug");
  EXPECT_EQ(c.log_file, std::filesystem::path("/var/log/imubridge.log"));
  EXPECT_EQ(c.stats_interval, 5s);
  EXPECT_EQ(c.params, std::filesystem::path("p.json"));
  EXPECT_EQ(c.store.path, "/data/flights.db");
  EXPECT_EQ(c.store.commit_interval, 100ms);
  EXPECT_EQ(c.store.max_size_bytes, 1572864u);  // 1.5 * 2^20
  EXPECT_EQ(c.store.min_free_bytes, 10u << 20);
  EXPECT_EQ(c.store.on_full, StoreConfig::OnFull::stop);
  ASSERT_TRUE(c.outputs.plotjuggler.has_value());
  EXPECT_EQ(c.outputs.plotjuggler->port, 9870);
  ASSERT_EQ(c.outputs.line_streams.size(), 2u);
  EXPECT_EQ(c.outputs.line_streams[1].kind, Endpoint::Kind::unix_listen);
  EXPECT_EQ(c.outputs.decimation, 4u);

  ASSERT_EQ(c.links.size(), 2u);
  const LinkConfig& radio = c.links[0];
  EXPECT_EQ(radio.name, "radio");
  EXPECT_TRUE(radio.device.path.empty());
  EXPECT_EQ(radio.device.usb_vid, 0x0403);
  EXPECT_EQ(radio.device.usb_pid, 0x6015);
  EXPECT_EQ(radio.device.usb_serial, "DN02ABCD");
  EXPECT_EQ(radio.format, protocol::WireFormat::xbee_escaped);
  EXPECT_EQ(radio.baud, 57600u);
  EXPECT_EQ(radio.reconnect_min, 50ms);
  EXPECT_EQ(radio.reconnect_max, 800ms);
  ASSERT_EQ(radio.bridge.size(), 1u);
  EXPECT_EQ(radio.bridge[0].port, 14550);
  EXPECT_TRUE(radio.feedback.enabled) << "a [link.feedback] table enables feedback unless it says otherwise";
  EXPECT_EQ(radio.feedback.rate_hz, 5.0);
  EXPECT_EQ(radio.feedback.xbee_destination64, 0x0013A20040A1B2C3u);
  const auto board = protocol::Calibration::reference_board();
  EXPECT_EQ(radio.calibration.gyro.sign, (std::array<std::int8_t, 3>{1, -1, -1}));
  EXPECT_EQ(radio.calibration.gyro.scale, board.gyro.scale) << "keys left out keep the reference board's values";
  EXPECT_EQ(radio.calibration.accel.scale, board.accel.scale);

  const LinkConfig& fc = c.links[1];
  EXPECT_EQ(fc.device.path, "/dev/ttyACM0");
  EXPECT_FALSE(fc.device.usb_vid.has_value());
  EXPECT_EQ(fc.format, protocol::WireFormat::mavlink);
  EXPECT_EQ(fc.baud, 115200u);
  EXPECT_FALSE(fc.feedback.enabled);
}

TEST(ConfigFile, TheShippedExampleIsValid) {
  const Config c = load_config(std::filesystem::path(IMUBRIDGE_SOURCE_DIR) / "systemd" / "imubridge.toml");
  EXPECT_NO_THROW(validate(c, "imubridge.toml"));
  EXPECT_EQ(c.store.path, "/var/lib/imubridge/imubridge.db");
}

TEST(ConfigFile, UnknownKeysAreNamedWithTheirLineAndLikelyMeaning) {
  EXPECT_EQ(error_of(kLink + "baudrate = 9600\n"),
            "test.toml:4: unknown key 'link[0].baudrate' (did you mean 'baud'?)");
  EXPECT_EQ(error_of("stat_interval_s = 3\n"),
            "test.toml:1: unknown key 'stat_interval_s' (did you mean 'stats_interval_s'?)");
  EXPECT_EQ(error_of("[store]\nmax_size_mb = 3\n"),
            "test.toml:2: unknown key 'store.max_size_mb' (did you mean 'max_size_mib'?)");
  EXPECT_EQ(error_of(kLink + "[link.calibration.accel]\nscal = [1, 1, 1]\n"),
            "test.toml:5: unknown key 'link[0].calibration.accel.scal' (did you mean 'scale'?)");
  EXPECT_EQ(error_of("colour = \"blue\"\n"), "test.toml:1: unknown key 'colour'");
}

TEST(ConfigFile, BadValuesAreNamedWithTheirLine) {
  EXPECT_EQ(error_of(kLink + "baud = \"fast\"\n"),
            "test.toml:4: 'link[0].baud' must be a whole number of bits per second, e.g. 115200");
  EXPECT_EQ(error_of("[store]\non_full = \"panic\"\n"), "test.toml:2: 'store.on_full' must be one of 'rotate', 'stop'");
  EXPECT_EQ(error_of("[store]\nmax_size_mib = 0.5\n"),
            "test.toml:2: 'store.max_size_mib' must be 0 (no cap) or at least 1");
  EXPECT_NE(error_of(kLink + "protocol = \"ubx\"\n").find("test.toml:4: 'link[0].protocol' "), std::string::npos);
  EXPECT_NE(error_of("[outputs]\nplotjuggler = \"udp://127.0.0.1\"\n").find("test.toml:2: 'outputs.plotjuggler' "),
            std::string::npos);
  EXPECT_NE(error_of(kLink + "[link.calibration.gyro]\nsign = [1, 2, 1]\n").find("'link[0].calibration' is not usable"),
            std::string::npos);
  EXPECT_NE(error_of("link = 3\n").find("'link' must be an array of tables"), std::string::npos);
  EXPECT_NE(error_of("[store\n").find("test.toml:1: "), std::string::npos);
}

// A rate the serial port cannot be set to would pass here and then fail at every reconnect: it is refused now.
TEST(ConfigFile, OnlyBaudRatesASerialPortTakesAreAccepted) {
  for (const char* rate : {"50", "9600", "115200", "921600", "1000000", "4000000"}) {
    EXPECT_EQ(error_of(kLink + "baud = " + rate + "\n"), "") << rate;
  }
  for (const char* rate : {"1", "12345", "100000000", "0", "-9600", "4000001"}) {
    const std::string error = error_of(kLink + "baud = " + rate + "\n");
    EXPECT_EQ(error.rfind("test.toml:4: 'link[0].baud' baud rate " + std::string(rate) +
                              " is not one a serial port can be set to (50, 75, ",
                          0),
              0u)
        << error;
    EXPECT_NE(error.find(", 115200, "), std::string::npos) << error;
    EXPECT_EQ(error.find('\n'), std::string::npos) << error;
  }
  EXPECT_EQ(error_of(kLink + "baud = 1e8\n"),
            "test.toml:4: 'link[0].baud' must be a whole number of bits per second, e.g. 115200");
  // A configuration assembled otherwise (the command line, a program) is checked as well.
  Config c;
  c.links.emplace_back().name = "imu";
  c.links[0].baud = 12345;
  try {
    validate(c, "");
    ADD_FAILURE() << "12345 baud accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("link[0] ('imu'): baud rate 12345 is not one"), std::string::npos) << e.what();
  }
}

TEST(ConfigFile, ADirectoryIsNotAConfigurationFile) {
  const auto dir = std::filesystem::temp_directory_path();
  try {
    load_config(dir);
    ADD_FAILURE() << "a directory was read as a configuration";
  } catch (const std::invalid_argument& e) {
    EXPECT_EQ(std::string(e.what()), dir.string() + ": is a directory, not a configuration file");
  }
}

TEST(ConfigFile, LinksMustBeUnambiguous) {
  EXPECT_EQ(error_of("[[link]]\ndevice = \"/dev/x\"\n"), "test.toml:1: 'link[0]' needs a 'name'");
  EXPECT_NE(error_of("[[link]]\nname = \"a\"\n").find("needs exactly one of 'device' (a path) and 'usb'"),
            std::string::npos);
  EXPECT_NE(error_of("[[link]]\nname = \"a\"\ndevice = \"/dev/x\"\nusb = { vid = 1, pid = 2 }\n")
                .find("needs exactly one of"),
            std::string::npos);
  EXPECT_NE(error_of("[[link]]\nname = \"a\"\nusb = { vid = 1 }\n").find("needs 'vid' and 'pid'"), std::string::npos);
  EXPECT_NE(error_of(kLink + kLink).find("the name is used twice"), std::string::npos);
  EXPECT_NE(error_of("[[link]]\nname = \"a/b\"\ndevice = \"/dev/x\"\n").find("'name' must be"), std::string::npos);
  EXPECT_NE(error_of(kLink + "reconnect_min_ms = 900\nreconnect_max_ms = 100\n").find("above reconnect_max_ms"),
            std::string::npos);
  EXPECT_NE(error_of(kLink + "protocol = \"mavlink\"\n[link.feedback]\nenabled = true\n").find("feedback:"),
            std::string::npos);
}

// A MAVLink link's one IMU: a message (and id) it keeps to, or, without them, the first IMU heard.
TEST(ConfigFile, AMavlinkLinkNamesItsImu) {
  const std::string mav = kLink + "protocol = \"mavlink\"\n";
  Config c = parse_config(mav + "imu = \"HIGHRES_IMU\"\nimu_id = 1\n", "test.toml");
  EXPECT_EQ(c.links[0].imu, "HIGHRES_IMU");
  EXPECT_EQ(c.links[0].imu_id, 1);
  EXPECT_EQ(mavlink_imu_lock(c.links[0]), (pipeline::MavlinkImuLock{.msgid = 105, .id = 1}));
  EXPECT_EQ(parse_config(to_toml(c), "snapshot").links[0].imu_id, 1);
  c = parse_config(mav, "test.toml");
  EXPECT_EQ(mavlink_imu_lock(c.links[0]), pipeline::MavlinkImuLock{}) << "the first IMU heard";
  EXPECT_FALSE(mavlink_imu_lock(parse_config(kLink, "test.toml").links[0]));
  EXPECT_EQ(mavlink_imu_lock(parse_config(mav + "imu = \"SCALED_IMU2\"\n", "test.toml").links[0]),
            (pipeline::MavlinkImuLock{.msgid = 116}));
  EXPECT_EQ(error_of(mav + "imu = \"ATTITUDE\"\n"),
            "test.toml:5: 'link[0].imu' must be one of 'HIGHRES_IMU', 'SCALED_IMU', 'SCALED_IMU2', 'SCALED_IMU3', "
            "'RAW_IMU'");
  EXPECT_NE(error_of(kLink + "imu = \"HIGHRES_IMU\"\n").find("'imu' and 'imu_id' are for MAVLink links"),
            std::string::npos);
  EXPECT_NE(error_of(mav + "imu = \"SCALED_IMU2\"\nimu_id = 1\n").find("SCALED_IMU2 has no id field"),
            std::string::npos);
}

TEST(ConfigFile, StreamRequestsNameMessagesAndRates) {
  const std::string mav = kLink + "protocol = \"mavlink\"\n";
  const Config c = parse_config(mav + "request_rates = { HIGHRES_IMU = 200, ATTITUDE = 0.5 }\n", "test.toml");
  EXPECT_EQ(c.links[0].request_rates, (std::map<std::string, double>{{"ATTITUDE", 0.5}, {"HIGHRES_IMU", 200}}));
  EXPECT_EQ(c.links[0].gcs_sysid, 255);
  EXPECT_EQ(c.links[0].gcs_compid, 190);
  EXPECT_EQ(parse_config(to_toml(c), "snapshot").links[0].request_rates, c.links[0].request_rates);
  EXPECT_EQ(error_of(mav + "request_rates = { HIGHRES = 200 }\n"),
            "test.toml:5: 'link[0].request_rates.HIGHRES' is not a MAVLink message name (e.g. HIGHRES_IMU, ATTITUDE)");
  EXPECT_NE(error_of(mav + "request_rates = { ATTITUDE = 5000 }\n").find("'link[0].request_rates.ATTITUDE'"),
            std::string::npos);
  EXPECT_NE(error_of(mav + "request_rates = { ATTITUDE = 0.01 }\n").find("'link[0].request_rates.ATTITUDE'"),
            std::string::npos);
  EXPECT_NE(error_of(kLink + "request_rates = { ATTITUDE = 5 }\n").find("'request_rates' is for MAVLink links"),
            std::string::npos);
}

// [sync]: the archive's URL without a password (the configuration is recorded with every session), where to read it.
TEST(ConfigFile, SyncNamesTheArchiveButNeverItsPassword) {
  const Config c = parse_config(
      "[sync]\nto = \"postgresql://gs@archive.lab/fleet\"\nstation = \"gs1\"\ninterval_s = 10\nchunks = true\n"
      "password_file = \"/etc/imubridge/archive.pass\"\n",
      "test.toml");
  ASSERT_TRUE(c.sync);
  EXPECT_EQ(c.sync->to, "postgresql://gs@archive.lab/fleet");
  EXPECT_EQ(c.sync->station, "gs1");
  EXPECT_EQ(c.sync->interval, 10s);
  EXPECT_TRUE(c.sync->chunks);
  EXPECT_EQ(c.sync->password_file, std::filesystem::path("/etc/imubridge/archive.pass"));
  EXPECT_EQ(parse_config(to_toml(c), "snapshot").sync, c.sync);
  EXPECT_EQ(parse_config("[sync]\nto = \"postgresql://a/b\"\n", "test.toml").sync->interval, 30s);
  EXPECT_EQ(error_of("[sync]\nto = \"postgresql://gs:secret@archive.lab/fleet\"\n"),
            "test.toml:2: 'sync.to' holds a password, which is never written in the configuration: use password_file "
            "or password_env");
  EXPECT_NE(error_of("[sync]\nto = \"postgresql://a/b\"\npassword = \"x\"\n").find("'sync.password' holds a password"),
            std::string::npos);
  EXPECT_NE(error_of("[sync]\ninterval_s = 5\n").find("'sync' needs 'to'"), std::string::npos);
  EXPECT_NE(error_of("[sync]\nto = \"mysql://a/b\"\n").find("'sync.to' must be a postgresql:// URL"),
            std::string::npos);
  EXPECT_NE(error_of("[sync]\nto = \"postgresql://a/b\"\nintervall_s = 5\n").find("did you mean 'interval_s'"),
            std::string::npos);
}

TEST(ConfigFile, FoxgloveServesLoopbackUnlessTheAddressIsGiven) {
  const Config defaults = parse_config("[outputs.foxglove]\n", "test.toml");
  ASSERT_TRUE(defaults.outputs.foxglove);
  EXPECT_EQ(defaults.outputs.foxglove->listen.host, "127.0.0.1");
  EXPECT_EQ(defaults.outputs.foxglove->listen.port, 8765);
  EXPECT_FALSE(parse_config("", "test.toml").outputs.foxglove);
  const Config c = parse_config(
      "[outputs.foxglove]\nlisten = \"[::]:9000\"\nsample_hz = 50\nestimate_hz = 0\nqueue = 100\n"
      "client_queue_kib = 256\n",
      "test.toml");
  ASSERT_TRUE(c.outputs.foxglove);
  EXPECT_EQ(c.outputs.foxglove->listen.host, "::");
  EXPECT_EQ(c.outputs.foxglove->listen.port, 9000);
  EXPECT_EQ(c.outputs.foxglove->sample_hz, 50);
  EXPECT_EQ(c.outputs.foxglove->estimate_hz, 0);
  EXPECT_EQ(c.outputs.foxglove->queue, 100u);
  EXPECT_EQ(c.outputs.foxglove->client_queue_bytes, 256u * 1024);
  EXPECT_EQ(parse_config(to_toml(c), "snapshot").outputs.foxglove, c.outputs.foxglove);
  EXPECT_EQ(parse_config("[outputs.foxglove]\nlisten = \"localhost:1\"\n", "t").outputs.foxglove->listen.host,
            "127.0.0.1");
  for (const char* bad : {"listen = \"ws://0.0.0.0:8765\"", "listen = \"station:8765\"", "listen = \"0.0.0.0\"",
                          "sample_hz = -1", "queue = 1", "client_queue_kib = 1", "listen = 8765"}) {
    const std::string key = std::string(bad).substr(0, std::string(bad).find(' '));
    EXPECT_NE(
        error_of(std::string("[outputs.foxglove]\n") + bad + "\n").find("test.toml:2: 'outputs.foxglove." + key + "'"),
        std::string::npos)
        << bad << ": " << error_of(std::string("[outputs.foxglove]\n") + bad + "\n");
  }
  EXPECT_NE(error_of("[outputs.foxglove]\nlistn = \"127.0.0.1:1\"\n").find("'outputs.foxglove.listn'"),
            std::string::npos);
}

TEST(ConfigFile, AFileWithoutLinksIsValidUntilNothingAddsAny) {
  Config c = parse_config("[store]\npath = \"x.db\"\n", "test.toml");
  EXPECT_THROW(validate(c, "test.toml"), std::invalid_argument);
  apply_link_spec(c, parse_link_spec("imu=/dev/ttyUSB0:imubridge"));
  EXPECT_NO_THROW(validate(c, "test.toml"));
}

TEST(ConfigFile, TheTomlSnapshotReadsBackToTheSameConfiguration) {
  const Config original = parse_config(R"(
params = "p.json"
[store]
max_size_mib = 3.25
[outputs]
line_streams = ["tcp-listen://127.0.0.1:9871"]
[[link]]
name = "radio"
usb = { vid = 0x0403, pid = 0x6015 }
protocol = "xbee"
[link.feedback]
rate_hz = 2.5
[link.calibration]
temperature_offset_c = 21.5
[link.calibration.accel]
scale = [0.1, 0.2, 0.30000000000000004]
)",
                                       "test.toml");
  const std::string text = to_toml(original);
  const Config copy = parse_config(text, "snapshot");
  EXPECT_EQ(to_toml(copy), text);
  EXPECT_EQ(copy.store.max_size_bytes, original.store.max_size_bytes);
  EXPECT_EQ(copy.links[0].device.usb_pid, 0x6015);
  EXPECT_FALSE(copy.links[0].device.usb_serial.has_value());
  EXPECT_EQ(copy.links[0].feedback.rate_hz, 2.5);
  EXPECT_EQ(copy.links[0].calibration, original.links[0].calibration) << "exact doubles, every field";
  EXPECT_EQ(copy.links[0].calibration.temperature_offset_c, 21.5);
  EXPECT_EQ(copy.outputs.line_streams[0].port, 9871);
}

TEST(ConfigFile, TheSnapshotOfAConfigurationWithoutLinksReadsBack) {
  const std::string text = to_toml(parse_config("", "empty.toml"));
  EXPECT_NE(text.find("link = []"), std::string::npos) << text;
  EXPECT_EQ(to_toml(parse_config(text, "snapshot")), text);
}

// Between them, these set every key of the file to something other than its default (password_file and
// password_env exclude each other, hence two).
const std::vector<std::string> kEveryKeySet = {R"(
log_level = "warn"
log_file = "/var/log/imubridge.log"
stats_interval_s = 7
params = "p.json"
[store]
path = "/data/flights.db"
commit_interval_ms = 150
max_size_mib = 2.5
min_free_mib = 64
on_full = "stop"
[outputs]
plotjuggler = "udp://127.0.0.1:9870"
line_streams = ["tcp-listen://127.0.0.1:9871"]
decimation = 3
[outputs.mqtt]
url = "mqtts://broker.lab:8884"
station = "field-1"
qos = 1
sample_hz = 20
estimate_hz = 5
keepalive_s = 45
reconnect_min_s = 2
reconnect_max_s = 60
outbox = 100
username = "gs"
password_file = "/etc/imubridge/mqtt.pass"
ca_file = "/etc/ssl/lab-ca.pem"
client_id = "gs-field-1"
protocol_version = "5"
[outputs.foxglove]
listen = "[::]:9000"
sample_hz = 25
estimate_hz = 0
queue = 100
client_queue_kib = 256
[sync]
to = "postgresql://gs@archive.lab/fleet"
station = "gs1"
interval_s = 10
chunks = true
password_env = "ARCHIVE_PASSWORD"
[[link]]
name = "fc"
device = "/dev/ttyACM0"
protocol = "mavlink"
baud = 921600
axes = "frd"
imu = "HIGHRES_IMU"
imu_id = 1
request_rates = { HIGHRES_IMU = 200 }
gcs_sysid = 250
gcs_compid = 191
bridge = ["udp://127.0.0.1:14550"]
reconnect_min_ms = 50
reconnect_max_ms = 800
[link.calibration]
temperature_offset_c = 21.5
[[link]]
name = "radio"
usb = { vid = 0x0403, pid = 0x6015, serial = "DN02ABCD" }
protocol = "xbee"
[link.feedback]
enabled = true
rate_hz = 2.5
xbee_destination64 = "0013A20040A1B2C3"
)",
                                               R"(
[outputs.mqtt]
url = "mqtt://broker.lab"
station = "field-2"
username = "gs"
password_env = "MQTT_PASSWORD"
[sync]
to = "postgresql://gs@archive.lab/fleet"
password_file = "/etc/imubridge/archive.pass"
)"};

// parse_config() and to_toml() share one table of keys; this holds every row of it to both directions, so a key
// added to the table is read and written back, or this fails naming it.
TEST(ConfigFile, EveryKeyOfTheTableSurvivesTheSnapshot) {
  std::set<std::string> keys, set_by_a_sample;
  for (const std::string& sample : kEveryKeySet) {
    const Config original = parse_config(sample, "sample.toml");
    const Config copy = parse_config(to_toml(original), "snapshot");
    for (const KeyComparison& key : compare_config_keys(original, copy)) {
      keys.insert(key.path);
      EXPECT_TRUE(key.equal) << key.path << " is not the same after to_toml() and parse_config()";
      if (!key.first_is_default) set_by_a_sample.insert(key.path);
    }
  }
  EXPECT_TRUE(keys.contains("link[].feedback.rate_hz") && keys.contains("outputs.mqtt.client_id")) << "nested keys";
  for (const std::string& key : keys) {
    EXPECT_TRUE(set_by_a_sample.contains(key)) << key << ": set it to other than its default in kEveryKeySet";
  }
}

TEST(LinkSpec, PathsUsbIdentitiesProtocolsAndBaudRates) {
  LinkSpec s = parse_link_spec("imu=/dev/ttyUSB0:imubridge");
  EXPECT_EQ(s.name, "imu");
  EXPECT_EQ(s.device.path, "/dev/ttyUSB0");
  EXPECT_EQ(s.format, protocol::WireFormat::imubridge);
  EXPECT_FALSE(s.baud.has_value());

  s = parse_link_spec("fc=/dev/serial/by-id/usb-a:b-if00:mavlink:921600");  // colons inside the path
  EXPECT_EQ(s.device.path, "/dev/serial/by-id/usb-a:b-if00");
  EXPECT_EQ(s.format, protocol::WireFormat::mavlink);
  EXPECT_EQ(s.baud, 921600u);

  s = parse_link_spec("radio=usb:0403:6015:DN02ABCD:xbee-escaped:57600");
  EXPECT_TRUE(s.device.path.empty());
  EXPECT_EQ(s.device.usb_vid, 0x0403);
  EXPECT_EQ(s.device.usb_pid, 0x6015);
  EXPECT_EQ(s.device.usb_serial, "DN02ABCD");
  EXPECT_EQ(s.format, protocol::WireFormat::xbee_escaped);
  EXPECT_EQ(s.baud, 57600u);

  for (const char* bad : {"/dev/ttyUSB0:imubridge", "imu=/dev/ttyUSB0", "imu=/dev/ttyUSB0:ubx", "imu=:imubridge",
                          "imu=usb:0403:imubridge", "imu=usb:xyz:6015:imubridge", "imu=/dev/x:imubridge:0"}) {
    EXPECT_THROW(parse_link_spec(bad), std::invalid_argument) << bad;
  }
}

// After a protocol, the last field is the baud rate, whatever it looks like: "-5" is a bad baud, not a protocol.
TEST(LinkSpec, ABadBaudRateIsCalledOne) {
  const auto error_of_spec = [](const std::string& spec) {
    try {
      parse_link_spec(spec);
      return std::string();
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
  };
  for (const char* rate : {"-5", "0", "12345", "100000000"}) {
    const std::string error = error_of_spec(std::string("imu=/dev/ttyUSB0:imubridge:") + rate);
    EXPECT_EQ(error.rfind("--link 'imu=/dev/ttyUSB0:imubridge:" + std::string(rate) + "': baud rate " + rate +
                              " is not one a serial port can be set to (",
                          0),
              0u)
        << error;
  }
  for (const char* rate : {"1e8", "fast", "+9600", "9600.0"}) {
    const std::string error = error_of_spec(std::string("imu=/dev/ttyUSB0:xbee:") + rate);
    EXPECT_EQ(error.rfind("--link 'imu=/dev/ttyUSB0:xbee:" + std::string(rate) + "': baud rate '" + rate +
                              "' is not a whole number",
                          0),
              0u)
        << error;
  }
  EXPECT_EQ(parse_link_spec("imu=/dev/ttyUSB0:imubridge:9600").baud, 9600u);
  EXPECT_NE(error_of_spec("imu=/dev/ttyUSB0:ubx").find("ubx"), std::string::npos) << "still an unknown protocol";
}

TEST(LinkSpec, TheCommandLineOverridesTheFilesLinkOfTheSameName) {
  Config c =
      parse_config(kLink + "protocol = \"xbee\"\nbaud = 57600\nbridge = [\"udp://127.0.0.1:14550\"]\n", "test.toml");
  apply_link_spec(c, parse_link_spec("imu=/dev/ttyUSB3:xbee-escaped"));
  apply_link_spec(c, parse_link_spec("other=/dev/ttyS1:mavlink:921600"));
  ASSERT_EQ(c.links.size(), 2u);
  EXPECT_EQ(c.links[0].device.path, "/dev/ttyUSB3");
  EXPECT_EQ(c.links[0].format, protocol::WireFormat::xbee_escaped);
  EXPECT_EQ(c.links[0].baud, 57600u) << "no baud in the spec: the file's stays";
  EXPECT_EQ(c.links[0].bridge.size(), 1u) << "settings the spec cannot express stay";
  EXPECT_EQ(c.links[1].name, "other");
  EXPECT_EQ(c.links[1].baud, 921600u);
}

}  // namespace
}  // namespace imubridge::daemon
