#include "protocol/mavlink_messages.hpp"

#include <algorithm>
#include <array>
#include <type_traits>
#include <utility>

#include "protocol/byte_order.hpp"

namespace imubridge::protocol::mavlink {
namespace {

struct CrcExtra {
  std::uint32_t msgid;
  std::uint8_t extra;
};

// CRC_EXTRA of every message in common.xml (which includes minimal.xml and standard.xml), sorted by id. Taken from
// MAVLink's generated C headers for common.xml; tests/mavlink_test.cpp recomputes several from the definitions.
constexpr CrcExtra kCrcExtras[] = {
    {0, 50},      {1, 124},     {2, 137},     {4, 237},     {5, 217},    {6, 104},    {7, 119},    {8, 117},
    {11, 89},     {20, 214},    {21, 159},    {22, 220},    {23, 168},   {24, 24},    {25, 23},    {26, 170},
    {27, 144},    {28, 67},     {29, 115},    {30, 39},     {31, 246},   {32, 185},   {33, 104},   {34, 237},
    {35, 244},    {36, 222},    {37, 212},    {38, 9},      {39, 254},   {40, 230},   {41, 28},    {42, 28},
    {43, 132},    {44, 221},    {45, 232},    {46, 11},     {47, 153},   {48, 41},    {49, 39},    {50, 78},
    {51, 196},    {54, 15},     {55, 3},      {61, 167},    {62, 183},   {63, 119},   {64, 191},   {65, 118},
    {66, 148},    {67, 21},     {69, 243},    {70, 124},    {73, 38},    {74, 20},    {75, 158},   {76, 152},
    {77, 143},    {80, 14},     {81, 106},    {82, 49},     {83, 22},    {84, 143},   {85, 140},   {86, 5},
    {87, 150},    {89, 231},    {90, 183},    {91, 63},     {92, 54},    {93, 47},    {100, 175},  {101, 102},
    {102, 158},   {103, 208},   {104, 56},    {105, 93},    {106, 138},  {107, 108},  {108, 32},   {109, 185},
    {110, 84},    {111, 34},    {112, 174},   {113, 124},   {114, 237},  {115, 4},    {116, 76},   {117, 128},
    {118, 56},    {119, 116},   {120, 134},   {121, 237},   {122, 203},  {123, 250},  {124, 87},   {125, 203},
    {126, 220},   {127, 25},    {128, 226},   {129, 46},    {130, 29},   {131, 223},  {132, 85},   {133, 6},
    {134, 229},   {135, 203},   {136, 1},     {137, 195},   {138, 109},  {139, 168},  {140, 181},  {141, 47},
    {142, 72},    {143, 131},   {144, 127},   {146, 103},   {147, 154},  {148, 178},  {149, 200},  {162, 189},
    {192, 36},    {225, 208},   {230, 163},   {231, 105},   {232, 151},  {233, 35},   {234, 150},  {235, 179},
    {241, 90},    {242, 104},   {243, 85},    {244, 95},    {245, 130},  {246, 184},  {247, 81},   {248, 8},
    {249, 204},   {250, 49},    {251, 170},   {252, 44},    {253, 83},   {254, 46},   {256, 71},   {257, 131},
    {258, 187},   {259, 92},    {260, 146},   {261, 179},   {262, 12},   {263, 133},  {264, 49},   {265, 26},
    {266, 193},   {267, 35},    {268, 14},    {269, 109},   {270, 59},   {271, 22},   {275, 126},  {276, 18},
    {277, 62},    {280, 70},    {281, 48},    {282, 123},   {283, 74},   {284, 99},   {285, 137},  {286, 210},
    {287, 1},     {288, 20},    {290, 251},   {291, 10},    {295, 234},  {296, 158},  {299, 19},   {300, 217},
    {301, 243},   {310, 28},    {311, 95},    {320, 243},   {321, 88},   {322, 243},  {323, 78},   {324, 132},
    {330, 23},    {331, 91},    {332, 236},   {333, 231},   {334, 72},   {335, 225},  {336, 245},  {339, 199},
    {340, 99},    {345, 209},   {350, 232},   {360, 11},    {361, 93},   {370, 75},   {371, 10},   {372, 26},
    {373, 117},   {375, 251},   {376, 199},   {380, 232},   {385, 147},  {386, 132},  {387, 4},    {388, 8},
    {390, 156},   {395, 0},     {396, 50},    {397, 182},   {400, 110},  {401, 183},  {410, 160},  {411, 106},
    {412, 33},    {413, 77},    {435, 134},   {436, 193},   {437, 30},   {440, 66},   {9000, 113}, {9005, 117},
    {12900, 114}, {12901, 254}, {12902, 140}, {12903, 249}, {12904, 77}, {12905, 49}, {12915, 94}, {12918, 139},
    {12919, 7},   {12920, 20}};
static_assert(std::ranges::is_sorted(kCrcExtras, {}, &CrcExtra::msgid));

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

std::optional<std::uint8_t> crc_extra(std::uint32_t msgid) {
  const auto* it = std::ranges::lower_bound(kCrcExtras, msgid, {}, &CrcExtra::msgid);
  if (it == std::end(kCrcExtras) || it->msgid != msgid) return std::nullopt;
  return it->extra;
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
