#pragma once
// The TOML configuration of `imubridge run` (/etc/imubridge/imubridge.toml); the --link shorthand is
// daemon/link_spec.hpp. Every key and its meaning: docs/config.md. A mistake is reported as one line naming the file,
// the line and the key, e.g.
//   imubridge.toml:7: unknown key 'link[0].baudrate' (did you mean 'baud'?)
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "daemon/config.hpp"
#include "pipeline/link_decoder.hpp"

namespace imubridge::daemon {

// Where `imubridge run` looks when no --config is given (a missing default file is not an error).
inline const std::filesystem::path kDefaultConfigPath = "/etc/imubridge/imubridge.toml";

// Parses TOML text; `source` names it in messages (a file name). Throws std::invalid_argument with one line for a
// syntax error, an unknown key, a wrongly typed or out-of-range value, or inconsistent links. A file without links
// is fine here: they may come from the command line.
Config parse_config(std::string_view toml_text, std::string_view source);
// Reads and parses a file; a file that cannot be read is a std::invalid_argument too.
Config load_config(const std::filesystem::path& path);

// The configuration as TOML that parse_config() reads back to the same Config: the session's config snapshot.
std::string to_toml(const Config& config);

// One key of the file in two configurations, compared through the table parse_config() and to_toml() share: for the
// test that every key survives to_toml() and parse_config(). Keys of array elements are named once: "link[].baud".
struct KeyComparison {
  std::string path;
  bool equal;             // the two hold the same value
  bool first_is_default;  // the first holds its struct's default
};
std::vector<KeyComparison> compare_config_keys(const Config& a, const Config& b);

// The line speeds a serial link can be set to: the termios B* rates Boost.Asio's serial_port knows on Linux, from 50
// to 4000000. Any other rate would pass here and then fail at every reconnect, so it is refused with the
// configuration. Throws std::invalid_argument naming the rate and the valid ones.
void check_baud(std::int64_t baud);
// The id of an IMU message a link's `imu` may name (HIGHRES_IMU, SCALED_IMU, SCALED_IMU2, SCALED_IMU3, RAW_IMU).
std::optional<std::uint32_t> mavlink_imu_msgid(std::string_view name);
// The id of a message of the MAVLink dialects imubridge knows (protocol/mavlink_message_specs.cpp), by name.
std::optional<std::uint32_t> mavlink_message_id(std::string_view name);
// A MAVLink link's IMU lock from its `imu` and `imu_id`; nothing for other links.
std::optional<pipeline::MavlinkImuLock> mavlink_imu_lock(const LinkConfig& link);

// The whole configuration, once assembled from the file and the command line: it names at least one link, and
// validate_links() (which parse_config() runs) finds nothing wrong with its links: names, backoff, feedback.
// `source` (the file, or empty when there is none) starts the message.
void validate(const Config& config, std::string_view source);
void validate_links(const Config& config, std::string_view source);

}  // namespace imubridge::daemon
