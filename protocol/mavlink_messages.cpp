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
template <typename... M>
constexpr bool sizes_agree(std::type_identity<std::variant<M...>>) {
  return ((fields_size<M>() == M::kLength) && ...);
}
static_assert(sizes_agree(std::type_identity<Decoded>{}));

template <typename T>
struct IsArray : std::false_type {};
template <typename T, std::size_t N>
struct IsArray<std::array<T, N>> : std::true_type {};

// A scalar field, or each element of an array field in turn.
template <typename T>
void load_field(T& field, const std::uint8_t* p) {
  if constexpr (IsArray<T>::value) {
    for (auto& element : field) {
      element = load_le<std::remove_reference_t<decltype(element)>>(p);
      p += sizeof element;
    }
  } else {
    field = load_le<T>(p);
  }
}

template <typename T>
void store_field(std::uint8_t* p, const T& field) {
  if constexpr (IsArray<T>::value) {
    for (const auto& element : field) {
      store_le(p, element);
      p += sizeof element;
    }
  } else {
    store_le(p, field);
  }
}

template <typename M>
M read(std::span<const std::uint8_t> payload) {
  std::array<std::uint8_t, M::kLength> bytes{};  // zero-filled, so a truncated payload's missing tail reads as 0
  std::copy_n(payload.begin(), std::min(payload.size(), bytes.size()), bytes.begin());
  M m;
  std::size_t at = 0;
  M::for_each_field(m, [&](std::string_view, auto& field) {
    load_field(field, &bytes[at]);
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
  // Every frame asks: the ids of MAVLink 1's range (where the IMU, attitude and position messages are) by index, the
  // rest by halves.
  static const std::array<const MessageSpec*, 256> kByLowId = [] {
    std::array<const MessageSpec*, 256> table{};
    for (const MessageSpec& spec : message_specs()) {
      if (spec.id < table.size()) table[spec.id] = &spec;
    }
    return table;
  }();
  if (msgid < kByLowId.size()) return kByLowId[msgid];
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

namespace {

template <typename M>
std::optional<ClockField> clock_field_of(std::size_t slot) {
  M m{};
  std::size_t offset = 0;
  std::optional<ClockField> out;
  M::for_each_field(m, [&](std::string_view name, const auto& field) {
    if (!out && (name == "time_usec" || name == "time_boot_ms"))
      out = ClockField{slot, offset, sizeof(field), name == "time_boot_ms" ? 1000u : 1u};
    offset += sizeof(field);
  });
  return out;
}

template <std::size_t... I>
std::array<std::pair<std::uint32_t, std::optional<ClockField>>, sizeof...(I)> clock_table(std::index_sequence<I...>) {
  return {
      {{std::variant_alternative_t<I, Decoded>::kId, clock_field_of<std::variant_alternative_t<I, Decoded>>(I)}...}};
}

const auto kClockTable = clock_table(std::make_index_sequence<kClockSlots>{});

}  // namespace

std::optional<ClockField> clock_field(std::uint32_t msgid) {
  for (const auto& [id, field] : kClockTable) {
    if (id == msgid) return field;
  }
  return std::nullopt;
}

std::optional<Decoded> decode_payload(std::uint32_t msgid, std::span<const std::uint8_t> payload) {
  return read_any(msgid, payload, std::type_identity<Decoded>{});
}

std::vector<std::uint8_t> encode_payload(const Decoded& message, bool extensions) {
  return std::visit(
      [extensions]<typename M>(const M& m) {
        std::vector<std::uint8_t> out(M::kLength);
        std::size_t at = 0;
        M::for_each_field(m, [&](std::string_view, const auto& field) {
          store_field(&out[at], field);
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
