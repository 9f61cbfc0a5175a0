#include "importers/tlog.hpp"

#include <iterator>

#include "protocol/mavlink.hpp"
#include "importers/file_bytes.hpp"

namespace imubridge::importers::tlog {
namespace {

namespace mavlink = protocol::mavlink;

struct Probe {
  enum class Kind { valid, cut_short, bad } kind = Kind::bad;
  std::uint32_t msgid = 0;
  bool verified = false;  // a valid record whose frame's CRC was checked
  bool other_layout = false;  // a valid record of a known id at a length its message cannot have
  std::size_t size = 0;   // the frame's, as its header gives it (0 when not even that could be read)
  const char* what = "";  // for a bad record
};

std::uint64_t load_time(const std::uint8_t* p) {
  std::uint64_t t = 0;
  for (int i = 0; i < 8; ++i) t = t << 8 | p[i];
  return t;
}

Probe probe(std::span<const std::uint8_t> bytes, std::size_t at) {
  if (bytes.size() - at <= kTimeSize) return {Probe::Kind::cut_short};  // the time, or no more than it
  const mavlink::FrameCheck check = mavlink::check_frame(bytes.subspan(at + kTimeSize));
  using Status = mavlink::FrameCheck::Status;
  switch (check.status) {
    case Status::frame:
      return {Probe::Kind::valid, check.msgid, true, false, check.size};
    case Status::unverified:
      return {Probe::Kind::valid, check.msgid, false, false, check.size};
    case Status::other_layout:
      return {Probe::Kind::valid, check.msgid, false, true, check.size};
    case Status::cut_short:
      return {Probe::Kind::cut_short, check.msgid, false, false, check.size};
    case Status::bad_crc:
      return {Probe::Kind::bad, check.msgid, false, false, check.size, "a frame that fails its CRC"};
    case Status::malformed:
      break;
  }
  return {Probe::Kind::bad, 0, false, false, 0, "not a MAVLink frame"};
}

// The next offset from `from` where reading can go on: a record with a checked frame, followed by another valid
// record or the end of the file, and stamped near the last good record's time when one is (a corrupt stretch may hold
// a frame by chance, hardly one at a time that fits too); failing that, any such record; the end when none is.
std::size_t resync(std::span<const std::uint8_t> bytes, std::size_t from, std::optional<std::uint64_t> last_us) {
  const auto find = [&](bool near_only) {
    for (std::size_t at = from; at + kTimeSize < bytes.size(); ++at) {
      const std::uint8_t stx = bytes[at + kTimeSize];
      if (stx != mavlink::kStxV1 && stx != mavlink::kStxV2) continue;
      const Probe p = probe(bytes, at);
      if (p.kind != Probe::Kind::valid || !p.verified) continue;
      if (near_only) {
        const std::uint64_t t = load_time(&bytes[at]);
        if ((t > *last_us ? t - *last_us : *last_us - t) > kResyncWindowUs) continue;
      }
      const std::size_t next = at + kTimeSize + p.size;
      if (next == bytes.size() || probe(bytes, next).kind == Probe::Kind::valid) return at;
    }
    return bytes.size();
  };
  if (last_us) {
    if (const std::size_t at = find(true); at < bytes.size()) return at;
  }
  return find(false);
}

}  // namespace

std::size_t Log::damaged_bytes() const {
  std::size_t n = 0;
  for (const Damage& d : damage) n += d.bytes;
  return n;
}

std::optional<std::string> Log::damage_summary() const {
  if (damage.empty()) return std::nullopt;
  std::string text = damage.size() == 1 ? ""
                                        : std::to_string(damage.size()) + " damaged stretches, " +
                                              std::to_string(damaged_bytes()) + " bytes: ";
  for (std::size_t i = 0; i < damage.size(); ++i) {
    const Damage& d = damage[i];
    if (i == 3) {
      text += "; and " + std::to_string(damage.size() - 3) + " more";
      break;
    }
    text += (i ? "; " : "") + std::to_string(d.bytes) + " bytes at byte " + std::to_string(d.offset) +
            (d.record == 0 ? " (before the first record)" : " (after record " + std::to_string(d.record) + ")") + ": " +
            d.what;
  }
  return text;
}

std::optional<std::string> Log::unverified_summary() const {
  if (unverified == 0) return std::nullopt;
  const auto list = [](const std::map<std::uint32_t, std::uint64_t>& ids) {
    std::uint64_t total = 0;
    std::string text;
    std::size_t shown = 0;
    for (const auto& [id, n] : ids) {
      total += n;
      if (shown++ < 8) text += (text.empty() ? "" : ", ") + std::to_string(id) + ": " + std::to_string(n);
    }
    if (ids.size() > 8) text += ", and " + std::to_string(ids.size() - 8) + " more ids";
    return std::to_string(total) + (total == 1 ? " frame" : " frames") + " (ids " + text + ")";
  };
  std::string text;
  if (!unknown_ids.empty()) text = list(unknown_ids) + " of message ids no dialect here knows";
  if (!other_layout_ids.empty()) {
    text += (text.empty() ? "" : "; ") + list(other_layout_ids) +
            " of known ids at a MAVLink 1 length their message cannot have (another dialect or version)";
  }
  return text;
}

Log parse(std::vector<std::uint8_t> file) {
  if (file.empty()) throw ParseError("not a MAVLink telemetry log (tlog): the file is empty");
  Log log;
  log.bytes = std::move(file);
  const std::span<const std::uint8_t> bytes(log.bytes);
  std::optional<std::uint64_t> last_us;
  std::size_t at = 0;
  while (at < bytes.size()) {
    const Probe p = probe(bytes, at);
    if (p.kind == Probe::Kind::valid) {
      const std::uint64_t t = load_time(&bytes[at]);
      log.records.push_back({t, at, p.size});
      if (!p.verified) {
        ++log.unverified;
        ++(p.other_layout ? log.other_layout_ids : log.unknown_ids)[p.msgid];
      }
      last_us = t;
      at += kTimeSize + p.size;
      continue;
    }
    const std::size_t next = resync(bytes, at + 1, last_us);
    std::string what = p.what;
    if (p.kind == Probe::Kind::cut_short) {
      what = next == bytes.size()
                 ? "the last record, cut short (" + std::to_string(bytes.size() - at) + " bytes" +
                       (p.size ? " of its " + std::to_string(kTimeSize + p.size) : std::string()) + "; the file ends)"
                 : "a frame longer than the bytes before the next record";
    }
    log.damage.push_back({at, next - at, log.records.size(), std::move(what)});
    at = next;
  }
  if (log.records.empty() || log.records.front().offset > kSniffBytes) {
    throw ParseError(
        "not a MAVLink telemetry log (tlog): no record (an 8-byte time, then a MAVLink frame) in its first " +
        std::to_string(kSniffBytes) + " bytes");
  }
  return log;
}

Log read_file(const std::filesystem::path& path) {
  auto bytes = read_file_bytes(path);
  if (!bytes) throw ParseError(path.string() + ": cannot be read");
  try {
    return parse(std::move(*bytes));
  } catch (const ParseError& e) {
    throw ParseError(path.string() + ": " + e.what());
  }
}

void append_record(std::vector<std::uint8_t>& out, std::uint64_t time_us, std::span<const std::uint8_t> frame) {
  for (int i = 7; i >= 0; --i) out.push_back(static_cast<std::uint8_t>(time_us >> (8 * i)));
  out.insert(out.end(), frame.begin(), frame.end());
}

}  // namespace imubridge::importers::tlog
