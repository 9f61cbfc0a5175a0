#pragma once
// Ceres reports through glog, which writes "E1124 ... covariance_impl.cc:...] ..." lines straight to stderr. Every
// failure those lines describe also reaches imubridge through Ceres' return values (a covariance that cannot be
// computed, a solver that did not converge), and the programs report it in their own words. So glog's lines go to
// spdlog at debug level (shown with a debug log level), never raw to stderr, and no glog files are written.
namespace imubridge::estimator {

// Idempotent; call once at start-up, before any solve.
void route_solver_logs_to_spdlog();

}  // namespace imubridge::estimator
