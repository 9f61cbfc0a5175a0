#pragma once
// What the three streaming decoders (imubridge, XBee, MAVLink) share, so that it is written once: the search for frame
// starts, the resync rule, any chunking, the end of the stream, and the byte accounting (docs/protocol.md, "What
// the decoders share"). A protocol supplies only where candidates may start, how to judge one, and what to do with a
// valid frame.
#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <span>
#include <utility>
#include <vector>

#include "protocol/decoder_counters.hpp"

namespace imubridge::protocol {

// A protocol's verdict on the candidate frame at a start byte.
enum class Verdict {
  need_more,    // undecided until more bytes arrive; at the end of the stream, a false start (cut off)
  noise,        // no candidate after all (e.g. the second sync byte is wrong): the start byte is noise
  false_start,  // rejected by its header, length or escaping
  bad_crc,      // rejected by its CRC or checksum (a false start too)
  unverified,   // nothing can check it (e.g. no CRC_EXTRA for its id): no frame, but no evidence of noise either
  frame,        // valid
};

struct Judgement {
  Verdict verdict;
  std::size_t size = 0;  // bytes of a valid frame
};

// The next byte equal to one of kStarts. memchr looks for one value, so each is searched for on its own and its hit
// remembered until passed: every byte is looked at once per value.
template <std::uint8_t... kStarts>
class StartFinder {
 public:
  StartFinder(const std::uint8_t* begin, const std::uint8_t* end) : end_(end), hits_{find(begin, kStarts)...} {}

  const std::uint8_t* next(const std::uint8_t* from) {
    // In a stream of frames the next one starts where the last one ended: no search then. (The hits kept stay right,
    // each being the first of its value at or after an earlier position.)
    if (from != end_ && ((*from == kStarts) || ...)) return from;
    const std::uint8_t* nearest = end_;
    for (std::size_t i = 0; i < hits_.size(); ++i) {
      if (hits_[i] < from) hits_[i] = find(from, kValues[i]);
      nearest = std::min(nearest, hits_[i]);
    }
    return nearest;
  }

 private:
  static constexpr std::array<std::uint8_t, sizeof...(kStarts)> kValues{kStarts...};

  const std::uint8_t* find(const std::uint8_t* from, std::uint8_t value) const {
    if (from == end_) return end_;  // an empty span may have a null pointer, which memchr must not get
    const void* hit = std::memchr(from, value, static_cast<std::size_t>(end_ - from));
    return hit ? static_cast<const std::uint8_t*>(hit) : end_;
  }

  const std::uint8_t* end_;
  std::array<const std::uint8_t*, sizeof...(kStarts)> hits_;
};

// Turns a protocol's framing into a streaming decoder. Protocol provides:
//   using Finder = StartFinder<...>;            the bytes a frame may start with
//   static constexpr std::size_t kMaxCandidate; bytes from a start byte that always decide its candidate
//   Judgement judge(std::span<const std::uint8_t> candidate, bool at_end);
//       the verdict on the candidate at candidate[0], given every byte available from there and whether more may
//       come. It must depend on nothing else, so that the chunking cannot change it, and once decided it must stay
//       decided as bytes are added.
//   bool take(std::span<const std::uint8_t> frame, Out& out, DecoderCounters& counters);
//       a frame judge() just found valid: appends it to `out` and returns true, or returns false to drop it (a
//       duplicate, or for imubridge an unknown type), whose bytes then count as discarded.
// The scanner counts bytes_in, frames_out, crc_failures, resyncs, unverified and bytes_discarded; take() counts the
// rest.
// Define judge() and take() `inline` in the protocol's .cpp: they run once per candidate and per frame, and a call
// each time costs about a quarter of the decoding time.
template <typename Protocol>
class StreamScanner {
 public:
  explicit StreamScanner(Protocol protocol = {}) : protocol_(std::move(protocol)) {}

  // Any chunking, 1 byte .. 64 KiB and beyond: when nothing is carried over the chunk is scanned where it lies, and
  // only an undecided candidate at its end is copied.
  template <typename Out>
  void feed(std::span<const std::uint8_t> chunk, Out& out) {
    counters_.bytes_in += chunk.size();
    if (!pending_.empty()) {
      // kMaxCandidate more bytes decide the carried candidate, so no more of the chunk than that is copied.
      const std::size_t carried = pending_.size();
      const std::size_t take = std::min(chunk.size(), Protocol::kMaxCandidate);
      pending_.insert(pending_.end(), chunk.begin(), chunk.begin() + static_cast<std::ptrdiff_t>(take));
      const std::size_t used = scan(pending_, false, out);
      if (used < carried) {  // still undecided, which means the whole chunk is now in pending_
        pending_.erase(pending_.begin(), pending_.begin() + static_cast<std::ptrdiff_t>(used));
        return;
      }
      pending_.clear();
      chunk = chunk.subspan(used - carried);
    }
    const std::size_t used = scan(chunk, false, out);
    pending_.assign(chunk.begin() + static_cast<std::ptrdiff_t>(used), chunk.end());
  }

  // End of stream: the carried bytes are scanned again knowing that no more will come, so a candidate cut off by the
  // end is a false start like any other and a frame inside it still comes out. Afterwards every byte given to feed()
  // is in an emitted frame or in bytes_discarded.
  template <typename Out>
  void finish(Out& out) {
    scan(pending_, true, out);
    pending_.clear();
  }

  const DecoderCounters& counters() const { return counters_; }

 private:
  // Decodes what `data` decides; returns how many leading bytes that used up (all of them when `at_end`). The rest
  // starts a candidate that needs more bytes.
  template <typename Out>
  std::size_t scan(std::span<const std::uint8_t> data, bool at_end, Out& out) {
    const std::uint8_t* const begin = data.data();
    const std::uint8_t* const end = begin + data.size();
    typename Protocol::Finder finder(begin, end);
    const std::uint8_t* p = begin;
    while (p < end) {
      const std::uint8_t* start = finder.next(p);
      counters_.bytes_discarded += static_cast<std::size_t>(start - p);
      p = start;
      if (p == end) break;

      auto [verdict, size] = protocol_.judge({p, end}, at_end);
      if (verdict == Verdict::need_more) {
        if (!at_end) return static_cast<std::size_t>(p - begin);
        verdict = Verdict::false_start;  // cut off by the end of the stream
      }
      if (verdict == Verdict::frame) {
        if (protocol_.take({p, size}, out, counters_)) {
          ++counters_.frames_out;
        } else {
          counters_.bytes_discarded += size;
        }
        p += size;
        continue;
      }
      // The resync rule: a rejected candidate gives up only its start byte, and the search resumes right after it,
      // so a frame that begins inside the rejected bytes is still found. An unverifiable candidate is no exception:
      // trusting its length would let noise that looks like one hide the frames it covers.
      counters_.crc_failures += verdict == Verdict::bad_crc;
      counters_.unverified += verdict == Verdict::unverified;
      counters_.resyncs += verdict == Verdict::false_start || verdict == Verdict::bad_crc;
      ++counters_.bytes_discarded;
      ++p;
    }
    return data.size();
  }

  Protocol protocol_;
  DecoderCounters counters_;
  std::vector<std::uint8_t> pending_;  // an undecided candidate carried over from the previous chunk
};

}  // namespace imubridge::protocol
