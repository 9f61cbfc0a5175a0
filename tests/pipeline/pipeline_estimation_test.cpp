// The samples -> estimates stage that live runs and replay share.
#include <gtest/gtest.h>

#include <cmath>

#include "pipeline/estimation_stage.hpp"
#include "pipeline/link_decoder.hpp"
#include "sim/frame_encoder.hpp"
#include "sim/scenario.hpp"
#include "tests/support/paper_params.hpp"

namespace imubridge::pipeline {
namespace {

std::vector<protocol::Sample> decoded_flight(const std::string& scenario, double seconds, std::uint32_t link) {
  const auto flight = sim::simulate(sim::make_scenario(scenario, 5, seconds));
  sim::FrameEncoder encoder(protocol::WireFormat::imubridge);
  LinkDecoder decoder(protocol::WireFormat::imubridge, protocol::Calibration::reference_board());
  std::vector<std::uint8_t> bytes;
  std::vector<protocol::Sample> samples;
  for (const auto& s : flight) encoder.encode(s, bytes);
  decoder.feed(bytes, 0, samples);
  for (auto& s : samples) s.source.link = link;  // as the engine keys them
  return samples;
}

using test::paper_params;

TEST(EstimationStage, EverySampleButTheLastDelayOnesGetsOneEstimateInOrder) {
  const auto samples = decoded_flight("paper", 3.0, 2);
  EstimationStage stage(paper_params());
  std::vector<store::Estimate> estimates;
  for (const auto& s : samples) {
    if (auto e = stage.update(s)) estimates.push_back(*e);
  }
  // The differentiator is centred delay samples back: the first delay samples have no past to differentiate
  // over, and the last delay samples no future yet.
  const auto delay = static_cast<std::size_t>(stage.delay_samples());
  ASSERT_EQ(estimates.size(), samples.size() - 2 * delay);
  for (std::size_t i = 0; i < estimates.size(); ++i) {
    const auto& sample = samples[i + delay];
    EXPECT_EQ(estimates[i].seq, sample.seq);
    EXPECT_EQ(estimates[i].link_id, 0);  // no store link: whoever stores it knows the sample's
    EXPECT_DOUBLE_EQ(estimates[i].t_s, sample.device_time_us * 1e-6);
    EXPECT_TRUE(std::isfinite(estimates[i].vx) && std::isfinite(estimates[i].vy));
  }
}

TEST(EstimationStage, SameSamplesSameParamsGiveBitIdenticalEstimates) {
  const auto samples = decoded_flight("paper", 2.0, 1);
  EstimationStage a(paper_params()), b(paper_params());
  for (const auto& s : samples) {
    const auto ea = a.update(s), eb = b.update(s);
    ASSERT_EQ(ea.has_value(), eb.has_value());
    if (ea) {
      EXPECT_EQ(*ea, *eb);  // exact, NaNs aside (none here)
    }
  }
}

TEST(EstimationStage, LinksDoNotMix) {
  const auto one = decoded_flight("paper", 1.0, 1);
  const auto other = decoded_flight("hover", 1.0, 2);
  EstimationStage alone(paper_params()), interleaved(paper_params());
  std::vector<store::Estimate> want, got;
  for (const auto& s : one) {
    if (auto e = alone.update(s)) want.push_back(*e);
  }
  for (std::size_t i = 0; i < one.size(); ++i) {
    if (auto e = interleaved.update(one[i])) got.push_back(*e);
    if (i < other.size()) (void)interleaved.update(other[i]);
  }
  EXPECT_EQ(got, want);
}

TEST(EstimationStage, UnidentifiedParamsStillCompensateButGiveNoVelocity) {
  const auto samples = decoded_flight("paper", 1.0, 1);
  EstimationStage stage(estimator::ModelParams{});
  std::size_t n = 0;
  for (const auto& s : samples) {
    if (auto e = stage.update(s)) {
      EXPECT_TRUE(std::isnan(e->vx) && std::isnan(e->vy));
      EXPECT_TRUE(std::isfinite(e->fx) && std::isfinite(e->fy));
      ++n;
    }
  }
  EXPECT_GT(n, 0u);
}

TEST(EstimationStage, RejectedSamplesGetNoEstimateAndShiftNothing) {
  auto samples = decoded_flight("paper", 1.0, 1);
  samples[50].accel[0] = std::nan("");  // a corrupt sample
  EstimationStage stage(paper_params());
  for (const auto& s : samples) {
    if (auto e = stage.update(s)) {
      EXPECT_NE(e->seq, samples[50].seq);
    }
  }
}

}  // namespace
}  // namespace imubridge::pipeline
