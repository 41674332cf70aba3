// Tests of resampling: summaries against long-double oracles, the systematic bound
// |count - N w_i| < 1, parallel == sequential bit for bit (sizes, weight shapes, grains, 1 and 2
// threads, all three schemes), agreement with a textbook (unblocked, long double) systematic
// draw, unbiasedness over many seeds with Hoeffding / binomial bounds, the degenerate inputs,
// the policy, and the one call the engine uses on a ParticleStore (maps shared, dead maps freed).
#include "parallel/resample.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <numbers>
#include <random>
#include <set>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "memory/node_heap.h"
#include "memory/particle_store.h"
#include "parallel/collective.h"
#include "parallel/internal/exp.h"
#include "parallel/random_stream.h"

namespace fastslam::parallel {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr ResampleScheme kSchemes[] = {ResampleScheme::kSystematic, ResampleScheme::kStratified,
                                       ResampleScheme::kMultinomial};

const char* name(ResampleScheme s) {
  switch (s) {
    case ResampleScheme::kSystematic:
      return "systematic";
    case ResampleScheme::kStratified:
      return "stratified";
    case ResampleScheme::kMultinomial:
      return "multinomial";
  }
  return "?";
}

enum class Shape {
  kUniform,      // all equal
  kGaussian,     // l ~ N(0, 1)
  kPeaked,       // l ~ N(0, 30): a few particles hold almost everything
  kSparse,       // two in three particles have weight zero (-inf)
  kOneSurvivor,  // exactly one finite log-weight, in the middle
  kLastOnly,     // only the last particle has weight
  kFarBelow,     // l ~ -1000 + N(0, 1): naive exp underflows, log-sum-exp must not
  kUnderflow,    // many weights underflow to zero after the shift
  kRamp,         // l_i = -0.01 i: a smooth tail
};
constexpr Shape kShapes[] = {Shape::kUniform,  Shape::kGaussian,    Shape::kPeaked,
                             Shape::kSparse,   Shape::kOneSurvivor, Shape::kLastOnly,
                             Shape::kFarBelow, Shape::kUnderflow,   Shape::kRamp};

std::vector<double> make_log_weights(std::size_t m, Shape shape, std::uint64_t seed = 1) {
  std::mt19937_64 gen(seed * 7919 + m);
  std::normal_distribution<double> normal(0.0, 1.0);
  std::vector<double> l(m, 0.0);
  for (std::size_t i = 0; i < m; ++i) {
    switch (shape) {
      case Shape::kUniform:
        l[i] = -3.0;
        break;
      case Shape::kGaussian:
        l[i] = normal(gen);
        break;
      case Shape::kPeaked:
        l[i] = 30.0 * normal(gen);
        break;
      case Shape::kSparse:
        l[i] = i % 3 == (m > 1 ? 1u : 0u) ? normal(gen) : -kInf;
        break;
      case Shape::kOneSurvivor:
        l[i] = i == m / 2 ? 5.0 : -kInf;
        break;
      case Shape::kLastOnly:
        l[i] = i + 1 == m ? -2.0 : -kInf;
        break;
      case Shape::kFarBelow:
        l[i] = -1000.0 + normal(gen);
        break;
      case Shape::kUnderflow:
        l[i] = i % 5 == 0 ? 0.0 : -800.0 - static_cast<double>(i % 7);
        break;
      case Shape::kRamp:
        l[i] = -0.01 * static_cast<double>(i);
        break;
    }
  }
  return l;
}

// Normalised weights in long double, the oracle.
std::vector<long double> oracle_weights(const std::vector<double>& l) {
  long double max = -std::numeric_limits<long double>::infinity();
  for (double v : l) {
    max = std::max<long double>(max, v);
  }
  long double sum = 0.0L;
  for (double v : l) {
    sum += std::exp(static_cast<long double>(v) - max);
  }
  std::vector<long double> w(l.size());
  for (std::size_t i = 0; i < l.size(); ++i) {
    w[i] = std::exp(static_cast<long double>(l[i]) - max) / sum;
  }
  return w;
}

std::vector<std::uint32_t> draw(ResampleScheme scheme, const std::vector<double>& l,
                                std::uint64_t seed, std::uint64_t step, std::size_t n,
                                const ParticleKernel& kernel) {
  std::vector<std::uint32_t> out(n);
  draw_ancestors(scheme, l, seed, step, out, kernel);
  return out;
}

std::vector<std::uint32_t> draw_sequential(ResampleScheme scheme, const std::vector<double>& l,
                                           std::uint64_t seed, std::uint64_t step, std::size_t n) {
  std::vector<std::uint32_t> out(n);
  draw_ancestors_sequential(scheme, l, seed, step, out);
  return out;
}

std::vector<std::size_t> copies(const std::vector<std::uint32_t>& ancestors, std::size_t m) {
  std::vector<std::size_t> c(m, 0);
  for (std::uint32_t a : ancestors) {
    ++c.at(a);
  }
  return c;
}

std::uint64_t bits(double x) { return std::bit_cast<std::uint64_t>(x); }

// ---------------------------------------------------------------- the exponential

TEST(Exp, WithinTwoUlpOfLongDoubleAndExactAtTheEnds) {
  std::mt19937_64 gen(1);
  std::uniform_real_distribution<double> wide(-708.0, 0.0), narrow(-1.0, 0.0);
  double worst = 0.0;
  for (int i = 0; i < 400000; ++i) {
    const double x = i % 2 == 0 ? wide(gen) : narrow(gen) * std::pow(10.0, -(i % 17));
    const long double exact = std::exp(static_cast<long double>(x));
    const double ulp =
        std::nextafter(static_cast<double>(exact), kInf) - static_cast<double>(exact);
    const double error = static_cast<double>(
        std::fabs((static_cast<long double>(internal::exp_nonpositive(x)) - exact) / ulp));
    worst = std::max(worst, error);
  }
  EXPECT_LT(worst, 2.0);
  EXPECT_EQ(internal::exp_nonpositive(0.0), 1.0);
  EXPECT_EQ(internal::exp_nonpositive(-0.0), 1.0);
  EXPECT_EQ(internal::exp_nonpositive(-kInf), 0.0);
  EXPECT_EQ(internal::exp_nonpositive(-708.5), 0.0);  // flushed, never subnormal
  EXPECT_GT(internal::exp_nonpositive(-708.0), 0.0);
  EXPECT_NEAR(internal::exp_nonpositive(-708.0) / std::exp(-708.0), 1.0, 1e-15);
}

// ---------------------------------------------------------------- summaries

TEST(WeightSummary, MatchesLongDoubleOracle) {
  const ParticleKernel kernel({.threads = 2, .grain = 512});
  for (std::size_t m : {1, 2, 100, 1000, 100000}) {
    for (Shape shape : kShapes) {
      const std::vector<double> l = make_log_weights(m, shape);
      const WeightSummary s = summarize_log_weights(l, kernel);
      long double max = -std::numeric_limits<long double>::infinity();
      for (double v : l) {
        max = std::max<long double>(max, v);
      }
      long double sum = 0.0L, square = 0.0L;
      for (double v : l) {
        const long double e = std::exp(static_cast<long double>(v) - max);
        sum += e;
        square += e * e;
      }
      const long double log_sum = max + std::log(sum);
      const long double ess = sum * sum / square;
      EXPECT_EQ(s.max_log_weight, static_cast<double>(max));
      EXPECT_NEAR(s.log_sum, static_cast<double>(log_sum),
                  1e-12 * std::max(1.0L, std::fabs(log_sum)));
      EXPECT_NEAR(s.effective_sample_size, static_cast<double>(ess), 1e-10 * ess);
      EXPECT_GE(s.effective_sample_size, 1.0 - 1e-12);
      EXPECT_LE(s.effective_sample_size, static_cast<double>(m) * (1 + 1e-12));
    }
  }
}

TEST(WeightSummary, UniformAndSingleParticleAreExact) {
  const ParticleKernel kernel({.threads = 2, .grain = 64});
  const std::vector<double> l(4096, 0.25);
  const WeightSummary s = summarize_log_weights(l, kernel);
  EXPECT_EQ(s.effective_sample_size, 4096.0);
  EXPECT_NEAR(s.log_sum, 0.25 + std::log(4096.0), 1e-14);
  const WeightSummary one = summarize_log_weights(std::vector<double>{-7.5}, kernel);
  EXPECT_EQ(one.effective_sample_size, 1.0);
  EXPECT_EQ(one.log_sum, -7.5);
  const WeightSummary survivor =
      summarize_log_weights(make_log_weights(1000, Shape::kOneSurvivor), kernel);
  EXPECT_EQ(survivor.effective_sample_size, 1.0);
  EXPECT_EQ(survivor.log_sum, 5.0);
}

TEST(WeightSummary, BitIdenticalForAnyThreadsAndGrain) {
  for (std::size_t m : {255, 257, 10007, 300000}) {
    for (Shape shape : {Shape::kGaussian, Shape::kPeaked, Shape::kSparse, Shape::kRamp}) {
      const std::vector<double> l = make_log_weights(m, shape);
      const ParticleKernel reference_kernel({.threads = 1, .grain = 1 << 30});
      const WeightSummary ref = summarize_log_weights(l, reference_kernel);
      for (unsigned threads : {1u, 2u}) {
        for (std::size_t grain : {1, 7, 256, 1000, 4096}) {
          const ParticleKernel kernel({.threads = threads, .grain = grain});
          const WeightSummary s = summarize_log_weights(l, kernel);
          ASSERT_EQ(bits(s.log_sum), bits(ref.log_sum)) << m << " " << threads << " " << grain;
          ASSERT_EQ(bits(s.effective_sample_size), bits(ref.effective_sample_size));
          ASSERT_EQ(bits(s.max_log_weight), bits(ref.max_log_weight));
        }
      }
    }
  }
}

// The cumulative weights themselves, bit for bit: the documented blocked scan computed here by
// hand, for any thread count and grain; monotone; a zero weight repeats its predecessor.
TEST(WeightSummary, CumulativeWeightsFollowTheFixedBlockScan) {
  constexpr std::size_t kBlock = ParticleKernel::kReduceBlock;
  for (std::size_t m : {1, 255, 256, 257, 5000, 200001}) {
    for (Shape shape : {Shape::kGaussian, Shape::kPeaked, Shape::kSparse, Shape::kUnderflow}) {
      const std::vector<double> l = make_log_weights(m, shape);
      const double max = *std::max_element(l.begin(), l.end());
      std::vector<double> expected(m);
      double offset = 0.0;
      for (std::size_t begin = 0; begin < m; begin += kBlock) {
        double local = 0.0;
        for (std::size_t i = begin; i < std::min(m, begin + kBlock); ++i) {
          local += internal::exp_nonpositive(l[i] - max);
          expected[i] = offset + local;
        }
        offset += local;
      }
      for (unsigned threads : {1u, 2u}) {
        for (std::size_t grain : {1, 100, 256, 3000}) {
          const ParticleKernel kernel({.threads = threads, .grain = grain});
          Resampler resampler({}, kernel);
          const WeightSummary s = resampler.summarize(l);
          ASSERT_EQ(bits(s.log_sum), bits(max + std::log(offset)));
          for (std::size_t i = 0; i < m; ++i) {
            const double c = resampler.cumulative_weight(i);
            ASSERT_EQ(bits(c), bits(expected[i])) << "particle " << i << " m " << m;
            if (i > 0) {
              ASSERT_GE(c, resampler.cumulative_weight(i - 1));
              if (l[i] == -kInf) {
                ASSERT_EQ(c, resampler.cumulative_weight(i - 1));
              }
            }
          }
        }
      }
    }
  }
}

TEST(WeightSummary, NormaliseMakesWeightsSumToOne) {
  const ParticleKernel kernel({.threads = 2, .grain = 100});
  for (Shape shape : kShapes) {
    std::vector<double> l = make_log_weights(5000, shape);
    const std::vector<double> before = l;
    const WeightSummary s = normalise_log_weights(l, kernel);
    long double sum = 0.0L;
    for (std::size_t i = 0; i < l.size(); ++i) {
      if (before[i] == -kInf) {
        EXPECT_EQ(l[i], -kInf);
      } else {
        EXPECT_EQ(l[i], before[i] - s.log_sum);
      }
      sum += std::exp(static_cast<long double>(l[i]));
    }
    EXPECT_NEAR(static_cast<double>(sum), 1.0, 1e-12);
    // Normalising twice changes (almost) nothing: the log-sum is now about 0.
    const WeightSummary again = normalise_log_weights(l, kernel);
    EXPECT_NEAR(again.log_sum, 0.0, 1e-12);
  }
}

// ---------------------------------------------------------------- degenerate input

TEST(Degenerate, NaNAnywhereIsAnErrorNamingTheParticle) {
  const ParticleKernel kernel({.threads = 2, .grain = 64});
  for (std::size_t m : {1, 1000, 1000000}) {
    for (std::size_t bad : {std::size_t{0}, m / 2, m - 1}) {
      std::vector<double> l = make_log_weights(m, Shape::kGaussian);
      l[bad] = kNaN;
      if (bad + 1 < m) {
        l[m - 1] = kNaN;  // a later NaN must not be the one named
      }
      const std::string expected = "particle " + std::to_string(bad) + " has log-weight NaN";
      try {
        summarize_log_weights(l, kernel);
        FAIL() << "no error for NaN at " << bad;
      } catch (const std::invalid_argument& e) {
        EXPECT_NE(std::string(e.what()).find(expected), std::string::npos) << e.what();
      }
      for (ResampleScheme scheme : kSchemes) {
        std::vector<std::uint32_t> out(m);
        EXPECT_THROW(draw_ancestors(scheme, l, 1, 2, out, kernel), std::invalid_argument);
        if (m <= 1000) {
          EXPECT_THROW(draw_ancestors_sequential(scheme, l, 1, 2, out), std::invalid_argument);
        }
      }
    }
  }
}

TEST(Degenerate, PlusInfinityIsAnError) {
  const ParticleKernel kernel({.threads = 2, .grain = 64});
  std::vector<double> l(700, 0.0);
  l[333] = kInf;
  try {
    summarize_log_weights(l, kernel);
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("particle 333 has log-weight +inf"), std::string::npos);
  }
  EXPECT_THROW(best_particle(l, kernel), std::invalid_argument);
}

TEST(Degenerate, AllWeightsZeroIsADomainError) {
  const ParticleKernel kernel({.threads = 2, .grain = 4096});
  for (std::size_t m : {1, 2, 1000, 1000000}) {
    const std::vector<double> l(m, -kInf);
    EXPECT_THROW(summarize_log_weights(l, kernel), std::domain_error);
    std::vector<std::uint32_t> out(m, 77);
    for (ResampleScheme scheme : kSchemes) {
      EXPECT_THROW(draw_ancestors(scheme, l, 3, 4, out, kernel), std::domain_error);
      if (m <= 1000) {
        EXPECT_THROW(draw_ancestors_sequential(scheme, l, 3, 4, out), std::domain_error);
      }
    }
    EXPECT_TRUE(std::all_of(out.begin(), out.end(), [](std::uint32_t a) { return a == 77; }));
    EXPECT_THROW(best_particle(l, kernel), std::domain_error);
  }
}

TEST(Degenerate, NoParticlesIsAnError) {
  const ParticleKernel kernel({.threads = 1, .grain = 64});
  EXPECT_THROW(summarize_log_weights({}, kernel), std::invalid_argument);
  std::vector<std::uint32_t> out(3);
  EXPECT_THROW(draw_ancestors(ResampleScheme::kSystematic, {}, 1, 1, out, kernel),
               std::invalid_argument);
  Resampler resampler({}, kernel);
  EXPECT_THROW(resampler.draw(ResampleScheme::kSystematic, 1, 1, out), std::logic_error);
}

TEST(Degenerate, DrawAfterAFailedSummarizeIsRefused) {
  const ParticleKernel kernel({.threads = 2, .grain = 64});
  Resampler resampler({}, kernel);
  std::vector<std::uint32_t> out(10);
  resampler.summarize(std::vector<double>(10, 0.0));
  resampler.draw(ResampleScheme::kSystematic, 1, 1, out);  // fine
  EXPECT_THROW(resampler.summarize(std::vector<double>(10, -kInf)), std::domain_error);
  EXPECT_THROW(resampler.draw(ResampleScheme::kSystematic, 1, 1, out), std::logic_error);
  std::vector<std::uint32_t> none;
  resampler.summarize(std::vector<double>(3, 1.0));
  resampler.draw(ResampleScheme::kMultinomial, 1, 1, none);  // zero draws: nothing happens
}

TEST(Degenerate, OneParticle) {
  const ParticleKernel kernel({.threads = 2, .grain = 64});
  for (ResampleScheme scheme : kSchemes) {
    for (std::size_t n : {1, 5}) {
      const auto out = draw(scheme, {-123.0}, 9, 9, n, kernel);
      EXPECT_EQ(out, std::vector<std::uint32_t>(n, 0)) << name(scheme);
      EXPECT_EQ(draw_sequential(scheme, {-123.0}, 9, 9, n), out);
    }
  }
}

TEST(Degenerate, FailedResampleLeavesTheStoreUnchanged) {
  memory::MallocHeap heap;
  const ParticleKernel kernel({.threads = 2, .grain = 64});
  memory::ParticleStore store(300, heap);
  for (std::size_t i = 0; i < store.size(); ++i) {
    store.x()[i] = static_cast<double>(i);
    store.log_weight()[i] = -kInf;
  }
  Resampler resampler({}, kernel);
  EXPECT_THROW(resampler.resample(store, 1, 1), std::domain_error);
  store.log_weight()[299] = kNaN;
  EXPECT_THROW(resampler.resample(store, 1, 1), std::invalid_argument);
  ASSERT_EQ(store.size(), 300u);
  for (std::size_t i = 0; i < store.size(); ++i) {
    EXPECT_EQ(store.x()[i], static_cast<double>(i));
    if (i < 299) {
      EXPECT_EQ(store.log_weight()[i], -kInf);
    }
  }
}

// ---------------------------------------------------------------- draws

TEST(Draw, SystematicCopiesAreWithinOneOfExpected) {
  const ParticleKernel kernel({.threads = 2, .grain = 256});
  for (std::size_t m : {1, 2, 3, 10, 100, 1000, 4097, 100000}) {
    for (Shape shape : kShapes) {
      const std::vector<double> l = make_log_weights(m, shape);
      const std::vector<long double> w = oracle_weights(l);
      for (std::size_t n : {m, 2 * m + 1, std::max<std::size_t>(1, m / 3)}) {
        for (std::uint64_t step = 0; step < 3; ++step) {
          const auto out = draw(ResampleScheme::kSystematic, l, 42, step, n, kernel);
          ASSERT_TRUE(std::is_sorted(out.begin(), out.end()));
          const auto c = copies(out, m);
          for (std::size_t i = 0; i < m; ++i) {
            const long double expected = static_cast<long double>(n) * w[i];
            ASSERT_LT(std::fabs(static_cast<long double>(c[i]) - expected), 1.0L + 1e-9L)
                << "particle " << i << " m " << m << " n " << n;
            if (w[i] == 0.0L) {
              ASSERT_EQ(c[i], 0u);
            }
          }
        }
      }
    }
  }
}

TEST(Draw, StratifiedCopiesAreWithinTwoOfExpected) {
  const ParticleKernel kernel({.threads = 2, .grain = 256});
  for (std::size_t m : {1, 7, 1000, 20000}) {
    for (Shape shape : kShapes) {
      const std::vector<double> l = make_log_weights(m, shape);
      const std::vector<long double> w = oracle_weights(l);
      const auto out = draw(ResampleScheme::kStratified, l, 5, 6, m, kernel);
      ASSERT_TRUE(std::is_sorted(out.begin(), out.end()));
      const auto c = copies(out, m);
      for (std::size_t i = 0; i < m; ++i) {
        // A particle's interval of length m w_i meets at most ceil(m w_i) + 1 strata.
        ASSERT_LT(std::fabs(static_cast<long double>(c[i]) - m * w[i]), 2.0L + 1e-9L);
        if (w[i] == 0.0L) {
          ASSERT_EQ(c[i], 0u);
        }
      }
    }
  }
}

TEST(Draw, ZeroWeightsAreNeverDrawn) {
  const ParticleKernel kernel({.threads = 2, .grain = 64});
  for (ResampleScheme scheme : kSchemes) {
    for (Shape shape : {Shape::kSparse, Shape::kOneSurvivor, Shape::kLastOnly, Shape::kUnderflow}) {
      for (std::size_t m : {1, 2, 255, 256, 257, 3000}) {
        const std::vector<double> l = make_log_weights(m, shape);
        const std::vector<long double> w = oracle_weights(l);
        for (std::uint64_t step = 0; step < 20; ++step) {
          for (std::uint32_t a : draw(scheme, l, 77, step, m, kernel)) {
            ASSERT_GT(w[a], 0.0L) << name(scheme) << " drew particle " << a;
          }
        }
      }
    }
  }
}

TEST(Draw, ParallelEqualsSequentialBitForBit) {
  struct Config {
    unsigned threads;
    std::size_t grain;
  };
  const std::vector<Config> all = {{1, 1},       {1, 7},    {1, 256},    {1, 1000}, {1, 2048},
                                   {1, 1 << 20}, {2, 1},    {2, 7},      {2, 256},  {2, 512},
                                   {2, 1000},    {2, 2048}, {2, 1 << 20}};
  const std::vector<Config> some = {{1, 1 << 20}, {2, 1}, {2, 512}, {2, 2048}};
  // Every shape and configuration for sizes around the block size; a few for the large ones.
  for (std::size_t m : {1, 2, 3, 255, 256, 257, 1000, 4097, 65537, 100000}) {
    const bool large = m > 5000;
    for (Shape shape : kShapes) {
      if (large && shape != Shape::kGaussian && shape != Shape::kSparse &&
          shape != Shape::kPeaked) {
        continue;
      }
      const std::vector<double> l = make_log_weights(m, shape);
      for (ResampleScheme scheme : kSchemes) {
        for (std::size_t n : {m, m + 300}) {
          const std::uint64_t seed = m * 31 + static_cast<std::uint64_t>(shape);
          const auto expected = draw_sequential(scheme, l, seed, 11, n);
          for (const Config& config : large ? some : all) {
            const ParticleKernel kernel({.threads = config.threads, .grain = config.grain});
            const auto got = draw(scheme, l, seed, 11, n, kernel);
            ASSERT_EQ(got, expected)
                << name(scheme) << " m " << m << " n " << n << " shape " << static_cast<int>(shape)
                << " threads " << config.threads << " grain " << config.grain;
          }
        }
      }
    }
  }
}

TEST(Draw, ResamplerGrainNeverChangesTheResult) {
  const ParticleKernel kernel({.threads = 2, .grain = 64});
  const std::vector<double> l = make_log_weights(20000, Shape::kPeaked);
  for (ResampleScheme scheme : kSchemes) {
    const auto expected = draw_sequential(scheme, l, 3, 3, 20001);
    for (std::size_t grain : {0, 1, 300, 5000, 1 << 20}) {
      Resampler resampler({}, kernel, grain);
      EXPECT_EQ(resampler.grain(), grain == 0 ? 64 : grain);
      const WeightSummary s = resampler.summarize(l);
      EXPECT_EQ(bits(s.log_sum), bits(summarize_log_weights(l, kernel).log_sum));
      std::vector<std::uint32_t> out(20001);
      resampler.draw(scheme, 3, 3, out);
      EXPECT_EQ(out, expected) << name(scheme) << " grain " << grain;
    }
  }
}

TEST(Draw, OneMillionParticles) {
  const std::size_t m = 1000000;
  const std::vector<double> l = make_log_weights(m, Shape::kGaussian);
  const std::vector<long double> w = oracle_weights(l);
  const ParticleKernel one({.threads = 1, .grain = 2048});
  const ParticleKernel two({.threads = 2, .grain = 2048});
  for (ResampleScheme scheme : kSchemes) {
    const auto a = draw(scheme, l, 2024, 1, m, one);
    const auto b = draw(scheme, l, 2024, 1, m, two);
    ASSERT_EQ(a, b) << name(scheme);
    ASSERT_EQ(a, draw_sequential(scheme, l, 2024, 1, m)) << name(scheme);
    if (scheme == ResampleScheme::kSystematic) {
      const auto c = copies(a, m);
      for (std::size_t i = 0; i < m; ++i) {
        ASSERT_LT(std::fabs(static_cast<long double>(c[i]) - m * w[i]), 1.0L + 1e-9L);
      }
    }
  }
}

// The textbook systematic draw (one cumulative sum in long double, no blocks): the blocked
// double scan must pick the same particles (a pointer would have to fall within ~1e-16 of a
// cumulative boundary to differ).
TEST(Draw, SystematicMatchesTextbookAlgorithm) {
  const ParticleKernel kernel({.threads = 2, .grain = 512});
  for (std::size_t m : {10, 1000, 50000}) {
    for (Shape shape : {Shape::kGaussian, Shape::kPeaked, Shape::kSparse, Shape::kRamp}) {
      const std::vector<double> l = make_log_weights(m, shape);
      const std::vector<long double> w = oracle_weights(l);
      for (std::uint64_t step = 0; step < 5; ++step) {
        RandomStream stream(StreamKey{99, step, 0, Purpose::kResample});
        const long double u = stream.uniform();
        std::vector<std::uint32_t> expected(m);
        std::size_t i = 0;
        long double c = w[0];
        for (std::size_t k = 0; k < m; ++k) {
          const long double p = (u + static_cast<long double>(k)) / static_cast<long double>(m);
          while (c <= p && i + 1 < m) {
            c += w[++i];
          }
          expected[k] = static_cast<std::uint32_t>(i);
        }
        EXPECT_EQ(draw(ResampleScheme::kSystematic, l, 99, step, m, kernel), expected);
      }
    }
  }
}

// Unbiasedness: the mean number of copies over S independent draws (steps) estimates N w_i.
// Systematic copies lie in {floor(N w_i), ceil(N w_i)}, an interval of width 1, so by Hoeffding
// P(|mean - N w_i| >= t) <= 2 exp(-2 S t^2); with a union bound over the M particles and a
// failure probability of 1e-9 per test, t = sqrt(ln(2 M / 1e-9) / (2 S)). Stratified copies lie
// in an interval of width 3 (t scales by 3).
TEST(Draw, SystematicAndStratifiedAreUnbiasedOverSeeds) {
  const ParticleKernel kernel({.threads = 2, .grain = 64});
  const std::size_t m = 40, samples = 20000;
  for (Shape shape : {Shape::kGaussian, Shape::kPeaked, Shape::kRamp, Shape::kSparse}) {
    const std::vector<double> l = make_log_weights(m, shape, 3);
    const std::vector<long double> w = oracle_weights(l);
    for (auto [scheme, width] : {std::pair{ResampleScheme::kSystematic, 1.0},
                                 std::pair{ResampleScheme::kStratified, 3.0}}) {
      Resampler resampler({}, kernel);
      resampler.summarize(l);
      std::vector<double> total(m, 0.0);
      std::vector<std::uint32_t> out(m);
      for (std::uint64_t step = 0; step < samples; ++step) {
        resampler.draw(scheme, 1234, step, out);
        for (std::uint32_t a : out) {
          total[a] += 1.0;
        }
      }
      const double t = width * std::sqrt(std::log(2.0 * m / 1e-9) / (2.0 * samples));
      for (std::size_t i = 0; i < m; ++i) {
        const double mean = total[i] / samples;
        EXPECT_NEAR(mean, static_cast<double>(m * w[i]), t)
            << name(scheme) << " particle " << i << " shape " << static_cast<int>(shape);
      }
    }
  }
}

// Multinomial: every draw is an independent categorical(w), so the pooled count of particle i
// over S draws of N is Binomial(S N, w_i): a z-score bound per particle (|z| < 5.5, with a
// union bound over 20 particles about 1e-6 false alarms) and a chi-square test of the whole
// histogram (19 degrees of freedom, threshold 60: p ~ 3e-6). The per-draw variance of a count
// must be the binomial N w (1 - w), far above systematic's (which is below 1/4).
TEST(Draw, MultinomialMatchesTheCategoricalDistribution) {
  const ParticleKernel kernel({.threads = 2, .grain = 64});
  const std::size_t m = 20, n = 20, samples = 20000;
  std::vector<double> l = make_log_weights(m, Shape::kGaussian, 5);
  l[3] = -kInf;
  const std::vector<long double> w = oracle_weights(l);
  Resampler resampler({}, kernel);
  resampler.summarize(l);
  std::vector<double> total(m, 0.0), square(m, 0.0);
  std::vector<std::uint32_t> out(n);
  for (std::uint64_t step = 0; step < samples; ++step) {
    resampler.draw(ResampleScheme::kMultinomial, 8, step, out);
    ASSERT_TRUE(std::is_sorted(out.begin(), out.end()));
    const auto c = copies(out, m);
    for (std::size_t i = 0; i < m; ++i) {
      total[i] += static_cast<double>(c[i]);
      square[i] += static_cast<double>(c[i] * c[i]);
    }
  }
  const double draws = static_cast<double>(n * samples);
  double chi2 = 0.0;
  for (std::size_t i = 0; i < m; ++i) {
    const double p = static_cast<double>(w[i]);
    if (p == 0.0) {
      EXPECT_EQ(total[i], 0.0);
      continue;
    }
    const double expected = draws * p;
    const double z = (total[i] - expected) / std::sqrt(expected * (1.0 - p));
    EXPECT_LT(std::fabs(z), 5.5) << "particle " << i;
    chi2 += (total[i] - expected) * (total[i] - expected) / expected;
    // Per-draw variance of the count: binomial n p (1 - p), sample estimate within 15 %
    // (its relative standard error is about sqrt(2 / S) ~ 1 %, plus kurtosis terms).
    const double mean = total[i] / samples;
    const double variance = square[i] / samples - mean * mean;
    const double binomial = n * p * (1.0 - p);
    if (binomial > 0.5) {
      EXPECT_NEAR(variance, binomial, 0.15 * binomial) << "particle " << i;
    }
  }
  EXPECT_LT(chi2, 60.0);
}

TEST(Draw, SystematicHasLowerVarianceThanMultinomial) {
  const ParticleKernel kernel({.threads = 1, .grain = 64});
  const std::size_t m = 50, samples = 4000;
  const std::vector<double> l = make_log_weights(m, Shape::kGaussian, 9);
  double variance[3] = {0, 0, 0};
  for (int s = 0; s < 3; ++s) {
    Resampler resampler({}, kernel);
    resampler.summarize(l);
    std::vector<double> total(m, 0.0), square(m, 0.0);
    std::vector<std::uint32_t> out(m);
    for (std::uint64_t step = 0; step < samples; ++step) {
      resampler.draw(kSchemes[s], 17, step, out);
      const auto c = copies(out, m);
      for (std::size_t i = 0; i < m; ++i) {
        total[i] += static_cast<double>(c[i]);
        square[i] += static_cast<double>(c[i] * c[i]);
      }
    }
    for (std::size_t i = 0; i < m; ++i) {
      const double mean = total[i] / samples;
      variance[s] += square[i] / samples - mean * mean;
    }
  }
  EXPECT_LT(variance[0], 0.25 * m);  // systematic: each count has variance <= 1/4
  EXPECT_LT(variance[0], variance[2]);
  EXPECT_LT(variance[1], variance[2]);
}

TEST(Draw, SchemesUseDifferentPointersButTheSameStreams) {
  const ParticleKernel kernel({.threads = 2, .grain = 64});
  const std::vector<double> l = make_log_weights(1000, Shape::kGaussian);
  // Different seeds and steps give different draws; the same key gives the same draw.
  for (ResampleScheme scheme : kSchemes) {
    EXPECT_EQ(draw(scheme, l, 1, 1, 1000, kernel), draw(scheme, l, 1, 1, 1000, kernel));
    EXPECT_NE(draw(scheme, l, 1, 1, 1000, kernel), draw(scheme, l, 1, 2, 1000, kernel));
    EXPECT_NE(draw(scheme, l, 1, 1, 1000, kernel), draw(scheme, l, 2, 1, 1000, kernel));
  }
}

// draw_ranges counts draw's ancestors: particle i's copies are the outputs [ends[i - 1],
// ends[i]), on one process and over ranks (threads of a LocalGroup, each its share), for every
// shape (zero weights, one survivor, underflow) and both schemes that work over ranks.
TEST(Draw, RangesCountTheAncestorsOnOneProcessAndOverRanks) {
  for (ResampleScheme scheme : {ResampleScheme::kSystematic, ResampleScheme::kStratified}) {
    for (Shape shape : kShapes) {
      for (std::size_t m : {1ul, 255ul, 257ul, 1500ul}) {
        SCOPED_TRACE(std::string(name(scheme)) + ", " + std::to_string(m) + " particles, shape " +
                     std::to_string(static_cast<int>(shape)));
        const std::vector<double> l = make_log_weights(m, shape);
        const ParticleKernel one({1, 64});
        const std::vector<std::uint32_t> ancestors = draw(scheme, l, 5, 9, m, one);
        std::vector<std::uint64_t> want(m, 0);  // one past the last output of particle i
        for (std::size_t k = 0; k < m; ++k) want[ancestors[k]] = k + 1;
        for (std::size_t i = 1; i < m; ++i) want[i] = std::max(want[i], want[i - 1]);
        Resampler alone({}, one);
        alone.summarize(l);
        std::vector<std::uint64_t> ends(m);
        EXPECT_EQ(alone.draw_ranges(scheme, 5, 9, ends), 0u);
        ASSERT_EQ(ends, want);
        const int most = static_cast<int>((m + ParticleKernel::kReduceBlock - 1) /
                                          ParticleKernel::kReduceBlock);
        for (int ranks = 2; ranks <= std::min(most, 4); ++ranks) {
          LocalGroup group(ranks);
          std::vector<std::thread> threads;
          for (int r = 0; r < ranks; ++r) {
            threads.emplace_back([&, r, member = group.member(r)] {
              const ParticleShare share = particle_share(m, ranks, r);
              const ParticleKernel kernel({2, 64});
              Resampler shared({}, kernel);
              const std::span<const double> mine(l.data() + share.first, share.count);
              shared.summarize(mine, SharedSet{member.get(), share.first, m});
              std::vector<std::uint64_t> got(share.count);
              const std::uint64_t start = shared.draw_ranges(scheme, 5, 9, got);
              EXPECT_EQ(start, share.first == 0 ? 0 : want[share.first - 1]) << "rank " << r;
              for (std::size_t i = 0; i < share.count; ++i) {
                EXPECT_EQ(got[i], want[share.first + i]) << "rank " << r << ", particle " << i;
              }
            });
          }
          for (std::thread& t : threads) t.join();
        }
      }
    }
  }
  const ParticleKernel kernel({1, 64});
  Resampler r({}, kernel);
  std::vector<std::uint64_t> ends(3);
  EXPECT_THROW(r.draw_ranges(ResampleScheme::kSystematic, 1, 1, ends), std::logic_error);
  r.summarize(std::vector<double>{0.0, 0.0, 0.0});
  EXPECT_THROW(r.draw_ranges(ResampleScheme::kMultinomial, 1, 1, ends), std::invalid_argument);
}

// The shared summary is the one-process summary on every rank, errors included: a NaN on one
// rank is reported, by its index in the set, on all.
TEST(WeightSummary, SharedSetsGiveTheOneProcessSummaryAndErrors) {
  constexpr std::size_t m = 1300;
  std::vector<double> l = make_log_weights(m, Shape::kPeaked);
  for (int pass = 0; pass < 2; ++pass) {
    const ParticleKernel one({1, 64});
    Resampler alone({}, one);
    std::string want_error;
    WeightSummary want{};
    try {
      want = alone.summarize(l);
    } catch (const std::invalid_argument& e) {
      want_error = e.what();
    }
    LocalGroup group(3);
    std::vector<std::thread> threads;
    for (int r = 0; r < 3; ++r) {
      threads.emplace_back([&, r, member = group.member(r)] {
        const ParticleShare share = particle_share(m, 3, r);
        const ParticleKernel kernel({1, 64});
        Resampler shared({}, kernel);
        try {
          const WeightSummary got = shared.summarize(
              std::span<const double>(l.data() + share.first, share.count),
              SharedSet{member.get(), share.first, m});
          EXPECT_TRUE(want_error.empty());
          EXPECT_EQ(std::bit_cast<std::uint64_t>(got.log_sum),
                    std::bit_cast<std::uint64_t>(want.log_sum));
          EXPECT_EQ(std::bit_cast<std::uint64_t>(got.effective_sample_size),
                    std::bit_cast<std::uint64_t>(want.effective_sample_size));
          for (std::size_t i = 0; i < share.count; i += 50) {
            EXPECT_EQ(shared.cumulative_weight(i), alone.cumulative_weight(share.first + i));
          }
        } catch (const std::invalid_argument& e) {
          EXPECT_EQ(std::string(e.what()), want_error) << "rank " << r;
        }
      });
    }
    for (std::thread& t : threads) t.join();
    l[1000] = std::numeric_limits<double>::quiet_NaN();  // on rank 2, for the second pass
  }
}

TEST(Draw, ResamplerReuseGivesTheSameResultsAsFreshBuffers) {
  const ParticleKernel kernel({.threads = 2, .grain = 300});
  Resampler resampler({}, kernel);
  for (std::size_t m : {100000, 10, 5000, 1, 70000}) {
    const std::vector<double> l = make_log_weights(m, Shape::kPeaked);
    resampler.summarize(l);
    for (ResampleScheme scheme : kSchemes) {
      std::vector<std::uint32_t> out(m);
      resampler.draw(scheme, 5, m, out);
      EXPECT_EQ(out, draw_sequential(scheme, l, 5, m, m));
    }
  }
}

// ---------------------------------------------------------------- policy and the store

TEST(Policy, ValidationAndDecision) {
  EXPECT_THROW(validate({.when = ResamplePolicy::When::kEssBelowFraction, .ess_fraction = 1.5}),
               std::invalid_argument);
  EXPECT_THROW(validate({.ess_fraction = -0.1}), std::invalid_argument);
  EXPECT_THROW(validate({.ess_fraction = kNaN}), std::invalid_argument);
  const ParticleKernel kernel({.threads = 1, .grain = 64});
  EXPECT_THROW(Resampler({.ess_fraction = 2.0}, kernel), std::invalid_argument);
  const ResamplePolicy every{};
  const ResamplePolicy half{.when = ResamplePolicy::When::kEssBelowFraction, .ess_fraction = 0.5};
  EXPECT_TRUE(should_resample(every, 100.0, 100));
  EXPECT_FALSE(should_resample(half, 50.0, 100));
  EXPECT_TRUE(should_resample(half, 49.9, 100));
  const ResamplePolicy never{.when = ResamplePolicy::When::kEssBelowFraction, .ess_fraction = 0.0};
  EXPECT_FALSE(should_resample(never, 1.0, 100));
}

// A store whose particle i has pose (i, -i, ...) and a map of its own with `landmarks` entries.
void fill_store(memory::ParticleStore& store, const std::vector<double>& log_weight,
                int landmarks) {
  for (std::size_t i = 0; i < store.size(); ++i) {
    store.x()[i] = static_cast<double>(i);
    store.y()[i] = -static_cast<double>(i);
    store.theta()[i] = 0.001 * static_cast<double>(i);
    store.log_weight()[i] = log_weight[i];
    for (int k = 0; k < landmarks; ++k) {
      store.map(i).insert({.x = static_cast<double>(i), .id = static_cast<std::uint64_t>(k)}, 0.0f);
    }
  }
}

TEST(ResampleStore, GathersPosesSharesMapsAndFreesTheDead) {
  const std::size_t m = 3000;
  const int landmarks = 20;
  const std::vector<double> l = make_log_weights(m, Shape::kPeaked, 4);
  std::vector<std::vector<double>> x_after;
  // The last: a per-call grain far below the resampler's (as after a heavy filter pass).
  const std::pair<unsigned, std::size_t> layouts[] = {{1u, 0}, {2u, 0}, {2u, 7}};
  for (const auto& [threads, call_grain] : layouts) {
    SCOPED_TRACE("threads " + std::to_string(threads) + ", grain " + std::to_string(call_grain));
    memory::MallocHeap heap;
    {
      const ParticleKernel kernel({.threads = threads, .grain = 128});
      memory::ParticleStore store(m, heap);
      fill_store(store, l, landmarks);
      const std::int64_t nodes_per_map = heap.stats().live_nodes / static_cast<std::int64_t>(m);
      ASSERT_EQ(heap.stats().live_nodes, nodes_per_map * static_cast<std::int64_t>(m));

      Resampler resampler({}, kernel);
      const ResampleOutcome outcome = resampler.resample(store, 2718, 3, call_grain);
      EXPECT_TRUE(outcome.resampled);
      const auto ancestors = resampler.last_ancestors();
      ASSERT_EQ(ancestors.size(), m);
      std::vector<std::uint32_t> expected(m);
      draw_ancestors_sequential(ResampleScheme::kSystematic, l, 2718, 3, expected);
      ASSERT_TRUE(std::equal(ancestors.begin(), ancestors.end(), expected.begin()));

      std::set<std::uint32_t> survivors(ancestors.begin(), ancestors.end());
      for (std::size_t k = 0; k < m; ++k) {
        ASSERT_EQ(store.x()[k], static_cast<double>(ancestors[k]));
        ASSERT_EQ(store.y()[k], -static_cast<double>(ancestors[k]));
        ASSERT_EQ(store.log_weight()[k], -std::log(static_cast<double>(m)));
        ASSERT_EQ(store.map(k).size(), static_cast<std::size_t>(landmarks));
        ASSERT_EQ(store.map(k).at(0).x, static_cast<double>(ancestors[k]));
        if (k > 0 && ancestors[k] == ancestors[k - 1]) {
          ASSERT_TRUE(store.map(k).shares_root_with(store.map(k - 1)));
        }
      }
      // Exactly the maps of the survivors are alive.
      EXPECT_EQ(heap.stats().live_nodes,
                nodes_per_map * static_cast<std::int64_t>(survivors.size()));
      x_after.emplace_back(store.x().begin(), store.x().end());
    }
    EXPECT_EQ(heap.stats().live_nodes, 0);
  }
  EXPECT_EQ(x_after[0], x_after[1]);
  EXPECT_EQ(x_after[0], x_after[2]);
}

// A store that carries each particle's covariance (FastSLAM 2.0 without odometry): resample
// moves it with its particle, whatever the thread count and grain; a store of indexed maps
// shares each survivor's tree and index together.
TEST(ResampleStore, CarriedCovarianceAndIndexedMapsFollowTheirParticle) {
  const std::size_t m = 2000;
  constexpr std::size_t kStride = memory::ParticleStore::kPoseCovStride;
  const std::vector<double> l = make_log_weights(m, Shape::kPeaked, 9);
  for (const auto& [threads, call_grain] :
       {std::pair<unsigned, std::size_t>{1u, 0}, {2u, 0}, {2u, 5}}) {
    memory::MallocHeap heap;
    {
      const ParticleKernel kernel({.threads = threads, .grain = 128});
      memory::ParticleStore store(m, heap,
                                  {memory::Indexing::kSpatial, memory::PoseCovariance::kCarried});
      fill_store(store, l, 3);
      for (std::size_t i = 0; i < store.pose_cov().size(); ++i) {
        store.pose_cov()[i] = static_cast<double>(i);
      }
      Resampler resampler({}, kernel);
      ASSERT_TRUE(resampler.resample(store, 99, 4, call_grain).resampled);
      const auto ancestors = resampler.last_ancestors();
      for (std::size_t k = 0; k < m; ++k) {
        for (std::size_t e = 0; e < kStride; ++e) {
          ASSERT_EQ(store.pose_cov()[k * kStride + e],
                    static_cast<double>(ancestors[k] * kStride + e));
        }
        ASSERT_EQ(store.map(k).index().size(), 3u);
        if (k > 0 && ancestors[k] == ancestors[k - 1]) {
          ASSERT_TRUE(store.map(k).shares_root_with(store.map(k - 1)));
        }
      }
    }
    EXPECT_EQ(heap.stats().live_nodes, 0);
  }
}

TEST(ResampleStore, PolicyBelowThresholdNormalisesInstead) {
  memory::MallocHeap heap;
  const ParticleKernel kernel({.threads = 2, .grain = 64});
  const std::size_t m = 1000;
  memory::ParticleStore store(m, heap);
  // Nearly uniform weights: N_eff close to M, above half of it.
  std::vector<double> l = make_log_weights(m, Shape::kGaussian);
  for (double& v : l) {
    v = 0.1 * v + 50.0;
  }
  fill_store(store, l, 1);
  Resampler resampler({.when = ResamplePolicy::When::kEssBelowFraction, .ess_fraction = 0.5},
                      kernel);
  const ResampleOutcome kept = resampler.resample(store, 1, 1);
  EXPECT_FALSE(kept.resampled);
  EXPECT_GT(kept.before.effective_sample_size, 0.5 * m);
  EXPECT_TRUE(resampler.last_ancestors().empty());
  long double sum = 0.0L;
  for (std::size_t i = 0; i < m; ++i) {
    EXPECT_EQ(store.x()[i], static_cast<double>(i));  // not resampled
    EXPECT_EQ(store.log_weight()[i], l[i] - kept.before.log_sum);
    sum += std::exp(static_cast<long double>(store.log_weight()[i]));
  }
  EXPECT_NEAR(static_cast<double>(sum), 1.0, 1e-12);
  // Now make the weights degenerate: N_eff drops, the store is resampled.
  for (std::size_t i = 0; i < m; ++i) {
    store.log_weight()[i] = i < 10 ? 0.0 : -50.0;
  }
  const ResampleOutcome resampled = resampler.resample(store, 1, 2);
  EXPECT_TRUE(resampled.resampled);
  EXPECT_LT(resampled.before.effective_sample_size, 0.5 * m);
  for (std::size_t i = 0; i < m; ++i) {
    EXPECT_LT(store.x()[i], 10.0);
  }
}

// ---------------------------------------------------------------- statistics

TEST(Statistics, WeightedMeanPoseMatchesOracleAndIsDeterministic) {
  memory::MallocHeap heap;
  const std::size_t m = 20000;
  memory::ParticleStore store(m, heap);
  const std::vector<double> l = make_log_weights(m, Shape::kGaussian);
  std::mt19937_64 gen(3);
  std::normal_distribution<double> normal(0.0, 1.0);
  long double sw = 0, sx = 0, sy = 0, sc = 0, ss = 0;
  const std::vector<long double> w = oracle_weights(l);
  for (std::size_t i = 0; i < m; ++i) {
    store.x()[i] = 10.0 + normal(gen);
    store.y()[i] = -4.0 + 2.0 * normal(gen);
    // Headings around pi: the circular mean must not average 3.1 and -3.1 to 0.
    store.theta()[i] = std::remainder(std::numbers::pi + 0.2 * normal(gen), 2 * std::numbers::pi);
    store.log_weight()[i] = l[i];
    sw += w[i];
    sx += w[i] * store.x()[i];
    sy += w[i] * store.y()[i];
    sc += w[i] * std::cos(static_cast<long double>(store.theta()[i]));
    ss += w[i] * std::sin(static_cast<long double>(store.theta()[i]));
  }
  const ParticleKernel reference({.threads = 1, .grain = 1 << 30});
  const WeightedPose ref = weighted_mean_pose(store, reference);
  EXPECT_NEAR(ref.x, static_cast<double>(sx / sw), 1e-10);
  EXPECT_NEAR(ref.y, static_cast<double>(sy / sw), 1e-10);
  EXPECT_NEAR(ref.theta, static_cast<double>(std::atan2(ss, sc)), 1e-10);
  EXPECT_GT(std::fabs(ref.theta), 3.0);
  for (unsigned threads : {1u, 2u}) {
    for (std::size_t grain : {1, 100, 256, 5000}) {
      const ParticleKernel kernel({.threads = threads, .grain = grain});
      const WeightedPose p = weighted_mean_pose(store, kernel);
      ASSERT_EQ(bits(p.x), bits(ref.x));
      ASSERT_EQ(bits(p.y), bits(ref.y));
      ASSERT_EQ(bits(p.theta), bits(ref.theta));
    }
  }
}

TEST(Statistics, BestParticleTakesTheLowestIndexAmongTies) {
  for (unsigned threads : {1u, 2u}) {
    const ParticleKernel kernel({.threads = threads, .grain = 64});
    std::vector<double> l(10000, -1.0);
    l[7000] = 3.0;
    l[9000] = 3.0;
    l[5] = -kInf;
    EXPECT_EQ(best_particle(l, kernel), 7000u);
    l[300] = 3.0;
    EXPECT_EQ(best_particle(l, kernel), 300u);
    EXPECT_EQ(best_particle(std::vector<double>{-kInf, -kInf, -2.0}, kernel), 2u);
  }
}

}  // namespace
}  // namespace fastslam::parallel
