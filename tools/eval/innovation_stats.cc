#include "tools/eval/innovation_stats.h"

#include <bit>
#include <cmath>
#include <cstdio>
#include <limits>

#include <nlohmann/json.hpp>

namespace fastslam::tools {

void InnovationStats::add(std::span<const engine::ObservationAssociation> scan) noexcept {
  for (const engine::ObservationAssociation& a : scan) {
    switch (a.outcome) {
      case engine::AssociationOutcome::kAssociated:
        break;
      case engine::AssociationOutcome::kNew:
        ++started_;
        continue;
      case engine::AssociationOutcome::kDiscarded:
        ++discarded_;
        continue;
    }
    ++associated_;
    const double d = a.mahalanobis2;
    if (std::isfinite(d)) {
      ++finite_;
      sum_ += d;
    }
    for (std::size_t k = 0; k < kPoints.size(); ++k) {
      if (!(d <= kPoints[k].bound)) ++beyond_[k];
    }
  }
}

double InnovationStats::mean() const noexcept {
  return finite_ == 0 ? std::numeric_limits<double>::quiet_NaN()
                      : sum_ / static_cast<double>(finite_);
}

double InnovationStats::beyond(std::size_t k) const noexcept {
  return associated_ == 0 ? std::numeric_limits<double>::quiet_NaN()
                          : static_cast<double>(beyond_[k]) / static_cast<double>(associated_);
}

InnovationStats InnovationStats::since(const InnovationStats& earlier) const noexcept {
  InnovationStats d;
  d.associated_ = associated_ - earlier.associated_;
  d.finite_ = finite_ - earlier.finite_;
  d.started_ = started_ - earlier.started_;
  d.discarded_ = discarded_ - earlier.discarded_;
  for (std::size_t k = 0; k < beyond_.size(); ++k) d.beyond_[k] = beyond_[k] - earlier.beyond_[k];
  d.sum_ = sum_ - earlier.sum_;
  return d;
}

std::optional<std::string> InnovationStats::warning() const {
  const std::size_t last = kPoints.size() - 1;
  if (associated_ < kMinimum || beyond(last) < kWide * kPoints[last].tail) return std::nullopt;
  char text[400];
  std::snprintf(text, sizeof text,
                "the innovations are wider than the filter's noise model: %.1f%% of the %llu "
                "associations lie beyond its 99%% bound (1%% expected), mean NIS %.2f (2 "
                "expected); widen the sensor noise (--sigma-range, --sigma-bearing) or the "
                "control noise (--sigma-u0, --sigma-u1)",
                100.0 * beyond(last), static_cast<unsigned long long>(associated_), mean());
  return std::string(text);
}

nlohmann::json InnovationStats::metrics() const {
  // JSON has no NaN: a run without associations reports null.
  auto number = [](double v) { return std::isnan(v) ? nlohmann::json() : nlohmann::json(v); };
  return {{"associated", associated_},
          {"started", started_},
          {"discarded", discarded_},
          {"nis_mean", number(mean())},
          {"beyond_chi2_50", number(beyond(0))},
          {"beyond_chi2_95", number(beyond(1))},
          {"beyond_chi2_99", number(beyond(2))}};
}

nlohmann::json InnovationStats::state() const {
  return {{"associated", associated_}, {"finite", finite_},
          {"started", started_},       {"discarded", discarded_},
          {"beyond", beyond_},         {"sum_bits", std::bit_cast<std::uint64_t>(sum_)}};
}

InnovationStats InnovationStats::from_state(const nlohmann::json& j) {
  InnovationStats s;
  s.associated_ = j.at("associated").get<std::uint64_t>();
  s.finite_ = j.at("finite").get<std::uint64_t>();
  s.started_ = j.at("started").get<std::uint64_t>();
  s.discarded_ = j.at("discarded").get<std::uint64_t>();
  s.beyond_ = j.at("beyond").get<std::array<std::uint64_t, kPoints.size()>>();
  s.sum_ = std::bit_cast<double>(j.at("sum_bits").get<std::uint64_t>());
  return s;
}

}  // namespace fastslam::tools
