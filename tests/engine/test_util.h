// Oracles shared by the engine tests: central-difference Jacobians (angle outputs wrapped), a
// relative matrix comparison, and random draws from a fixed-seed local generator.
#pragma once

#include <array>
#include <cmath>
#include <random>

#include <Eigen/Core>
#include <gtest/gtest.h>

#include "engine/angles.h"
#include "engine/motion_model.h"

namespace fastslam::engine::testing {

// d f / d x at x by central differences with step h per input; output components whose flag in
// `wrapped` is set are angles, so their differences are wrapped to (-pi, pi].
template <int Out, int In, class F>
Eigen::Matrix<double, Out, In> numeric_jacobian(F&& f, const Eigen::Matrix<double, In, 1>& x,
                                                std::array<bool, Out> wrapped, double h = 1e-5) {
  Eigen::Matrix<double, Out, In> j;
  for (int i = 0; i < In; ++i) {
    Eigen::Matrix<double, In, 1> plus = x;
    Eigen::Matrix<double, In, 1> minus = x;
    plus[i] += h;
    minus[i] -= h;
    const Eigen::Matrix<double, Out, 1> fp = f(plus);
    const Eigen::Matrix<double, Out, 1> fm = f(minus);
    for (int o = 0; o < Out; ++o) {
      const double diff = wrapped[o] ? angle_diff(fp[o], fm[o]) : fp[o] - fm[o];
      j(o, i) = diff / (2.0 * h);
    }
  }
  return j;
}

// True when every entry of a and b agrees to abs_tol + rel_tol * max(|a_ij|, |b_ij|).
template <class A, class B>
::testing::AssertionResult matrices_near(const A& a, const B& b, double abs_tol, double rel_tol) {
  if (a.rows() != b.rows() || a.cols() != b.cols()) {
    return ::testing::AssertionFailure() << "shapes differ";
  }
  for (int r = 0; r < a.rows(); ++r) {
    for (int c = 0; c < a.cols(); ++c) {
      const double x = a(r, c);
      const double y = b(r, c);
      const double tol = abs_tol + rel_tol * std::max(std::abs(x), std::abs(y));
      if (!(std::abs(x - y) <= tol)) {
        return ::testing::AssertionFailure()
               << "entry (" << r << ", " << c << "): " << x << " vs " << y << " (diff " << x - y
               << ", tol " << tol << ")\nfirst:\n"
               << a << "\nsecond:\n"
               << b;
      }
    }
  }
  return ::testing::AssertionSuccess();
}

// A heading uniform in (-pi, pi], with one draw in four within 1e-3 of +-pi (the wrap seam).
inline double random_heading(std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(-kPi, kPi);
  std::uniform_real_distribution<double> seam(0.0, 1e-3);
  std::uniform_int_distribution<int> pick(0, 3);
  switch (pick(rng)) {
    case 0:
      return kPi - seam(rng);
    case 1:
      return -kPi + seam(rng);
    default:
      return u(rng);
  }
}

// The Victoria Park car's geometry (../shared/data/victoria_park/README.md), the Ackermann
// model's test case.
inline constexpr AckermannGeometry kVictoriaParkCar{3.78, 0.50, 2.83, 0.76};

}  // namespace fastslam::engine::testing
