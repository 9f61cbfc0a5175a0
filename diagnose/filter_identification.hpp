#pragma once
// `imubridge identify --velocity filter`: the paper's or the 3-D model identified from the IMU alone by the filter
// error method (docs/identification.md, "From the IMU alone"). It is diagnose's model with the drag-velocity filter
// as its velocity (velocity `filter`) and the effects that make up identify's blocks, fitted once: one
// mechanism for identify and diagnose.
#include "estimator/imu_series.hpp"
#include "identification/identify.hpp"

namespace imubridge::diagnose {

// `options.velocity` must be velocity `filter`; the method is LM whatever `options.method` says (the GA would run the
// filter over the flight for every individual). --hold applies to the drag and bias blocks; the lever arm and mounting
// are always fitted. Throws std::invalid_argument for an invalid series, empty windows or a block that cannot be held.
estimator::IdentifyResult identify_by_filter_error(const estimator::ImuSeries& series,
                                                   const estimator::IdentifyOptions& options);

}  // namespace imubridge::diagnose
