#include "pipeline/session_config.hpp"

#include <stdexcept>

namespace imubridge::pipeline {
namespace {

using nlohmann::json;

json axis_to_json(const protocol::AxisCalibration& a) {
  return {{"scale", a.scale}, {"offset", a.offset}, {"source_axis", a.source_axis}, {"sign", a.sign}};
}

protocol::AxisCalibration axis_from_json(const json& j, const char* name) {
  protocol::AxisCalibration a;
  try {
    j.at("scale").get_to(a.scale);
    j.at("offset").get_to(a.offset);
    j.at("source_axis").get_to(a.source_axis);
    j.at("sign").get_to(a.sign);
  } catch (const json::exception& e) {
    throw std::invalid_argument(std::string("calibration.") + name + ": " + e.what());
  }
  if (!a.valid()) throw std::invalid_argument(std::string("calibration.") + name + " is not a valid calibration");
  return a;
}

}  // namespace

json calibration_to_json(const protocol::Calibration& c) {
  return {{"accel", axis_to_json(c.accel)},
          {"gyro", axis_to_json(c.gyro)},
          {"mag", axis_to_json(c.mag)},
          {"temperature_scale", c.temperature_scale},
          {"temperature_offset_c", c.temperature_offset_c}};
}

protocol::Calibration calibration_from_json(const json& j) {
  protocol::Calibration c;
  c.accel = axis_from_json(j.at("accel"), "accel");
  c.gyro = axis_from_json(j.at("gyro"), "gyro");
  c.mag = axis_from_json(j.at("mag"), "mag");
  c.temperature_scale = j.at("temperature_scale").get<double>();
  c.temperature_offset_c = j.at("temperature_offset_c").get<double>();
  return c;
}

void add_recorded_links(json& config, const std::vector<RecordedLink>& links) {
  json& out = config["links"] = json::array();
  for (const auto& link : links) {
    json& j = out.emplace_back(json{{"name", link.name},
                                    {"protocol", protocol::wire_format_name(link.format)},
                                    {"calibration", calibration_to_json(link.calibration)},
                                    {"imu_axes", link.imu_axes}});
    if (const auto& imu = link.mavlink_imu) {
      const protocol::mavlink::MessageSpec* spec = protocol::mavlink::message_spec(imu->msgid);
      j["mavlink_imu"] = {{"message", spec ? spec->name : ""},  // for people; msgid is what is read back
                          {"msgid", imu->msgid},
                          {"sysid", imu->sysid},
                          {"compid", imu->compid},
                          {"id", imu->id}};
    }
    if (const auto& lock = link.mavlink_imu_lock) {
      json& l = j["mavlink_imu_lock"] = json::object();
      if (lock->msgid) {
        const protocol::mavlink::MessageSpec* spec = protocol::mavlink::message_spec(*lock->msgid);
        l["message"] = spec ? spec->name : "";  // for people
        l["msgid"] = *lock->msgid;
      }
      if (lock->id) l["id"] = *lock->id;
    }
  }
}

std::vector<RecordedLink> recorded_links(const std::string& session_config_json) {
  const json config = json::parse(session_config_json, nullptr, /*allow_exceptions=*/false);
  if (config.is_discarded() || !config.contains("links") || !config["links"].is_array()) {
    throw std::invalid_argument("the session's config snapshot records no links (not written by imubridge?)");
  }
  std::vector<RecordedLink> links;
  for (const auto& j : config["links"]) {
    try {
      RecordedLink& link = links.emplace_back(RecordedLink{
          j.at("name").get<std::string>(), protocol::parse_wire_format(j.at("protocol").get<std::string>()),
          calibration_from_json(j.at("calibration")), j.value("imu_axes", std::string("auto"))});
      if (j.contains("mavlink_imu")) {
        const json& imu = j.at("mavlink_imu");
        link.mavlink_imu = protocol::mavlink::ImuSource{.msgid = imu.at("msgid").get<std::uint32_t>(),
                                                        .sysid = imu.at("sysid").get<std::uint8_t>(),
                                                        .compid = imu.at("compid").get<std::uint8_t>(),
                                                        .id = imu.at("id").get<std::uint8_t>()};
      }
      if (j.contains("mavlink_imu_lock")) {
        const json& lock = j.at("mavlink_imu_lock");
        MavlinkImuLock& l = link.mavlink_imu_lock.emplace();
        if (lock.contains("msgid")) l.msgid = lock.at("msgid").get<std::uint32_t>();
        if (lock.contains("id")) l.id = lock.at("id").get<std::uint8_t>();
      }
    } catch (const json::exception& e) {
      throw std::invalid_argument(std::string("session config, links: ") + e.what());
    }
  }
  return links;
}

LinkDecoder make_decoder(const RecordedLink& link) {
  LinkDecoder decoder(link.format, link.calibration, link.mavlink_imu);
  if (link.mavlink_imu_lock) decoder.lock_mavlink_imu(*link.mavlink_imu_lock);
  return decoder;
}

}  // namespace imubridge::pipeline
