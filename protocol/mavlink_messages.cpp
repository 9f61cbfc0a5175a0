#include "protocol/mavlink_messages.hpp"

#include <algorithm>
#include <array>
#include <type_traits>
#include <utility>

#include "protocol/byte_order.hpp"

namespace imubridge::protocol::mavlink {
namespace {

template <typename M>
constexpr std::size_t fields_size() {
  std::size_t size = 0;
  M m;
  M::for_each_field(m, [&](std::string_view, const auto& field) { size += sizeof field; });
  return size;
}
static_assert(fields_size<HighresImu>() == HighresImu::kLength && fields_size<ScaledImu>() == ScaledImu::kLength &&
              fields_size<RawImu>() == RawImu::kLength && fields_size<Attitude>() == Attitude::kLength);

template <typename M>
M read(std::span<const std::uint8_t> payload) {
  std::array<std::uint8_t, M::kLength> bytes{};  // zero-filled, so a truncated payload's missing tail reads as 0
  std::copy_n(payload.begin(), std::min(payload.size(), bytes.size()), bytes.begin());
  M m;
  std::size_t at = 0;
  M::for_each_field(m, [&](std::string_view, auto& field) {
    field = load_le<std::remove_reference_t<decltype(field)>>(&bytes[at]);
    at += sizeof field;
  });
  return m;
}

// Decoded's alternatives drive both functions below, so adding a message type is adding it to Decoded.
template <typename... M>
bool has_id(std::uint32_t msgid, std::type_identity<std::variant<M...>>) {
  return ((msgid == M::kId) || ...);
}

template <typename... M>
std::optional<Decoded> read_any(std::uint32_t msgid, std::span<const std::uint8_t> payload,
                                std::type_identity<std::variant<M...>>) {
  std::optional<Decoded> decoded;
  (void)((msgid == M::kId && (decoded = read<M>(payload), true)) || ...);  // stops at the match
  return decoded;
}

}  // namespace

const MessageSpec* message_spec(std::uint32_t msgid) {
  const std::span<const MessageSpec> specs = message_specs();
  const auto it = std::ranges::lower_bound(specs, msgid, {}, &MessageSpec::id);
  return it != specs.end() && it->id == msgid ? &*it : nullptr;
}

std::optional<std::uint8_t> crc_extra(std::uint32_t msgid) {
  const MessageSpec* spec = message_spec(msgid);
  if (!spec) return std::nullopt;
  return spec->crc_extra;
}

bool is_decoded(std::uint32_t msgid) { return has_id(msgid, std::type_identity<Decoded>{}); }

std::optional<Decoded> decode_payload(std::uint32_t msgid, std::span<const std::uint8_t> payload) {
  return read_any(msgid, payload, std::type_identity<Decoded>{});
}

std::vector<std::uint8_t> encode_payload(const Decoded& message, bool extensions) {
  return std::visit(
      [extensions]<typename M>(const M& m) {
        std::vector<std::uint8_t> out(M::kLength);
        std::size_t at = 0;
        M::for_each_field(m, [&](std::string_view, const auto& field) {
          store_le(&out[at], field);
          at += sizeof field;
        });
        out.resize(extensions ? M::kLength : M::kBaseLength);
        return out;
      },
      message);
}

std::uint32_t message_id(const Decoded& message) {
  return std::visit([]<typename M>(const M&) { return M::kId; }, message);
}

}  // namespace imubridge::protocol::mavlink
