// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Portable, seeded random numbers for the virtual rig. std::mt19937_64 is fully specified by
// the standard, but the std:: distributions are not (their output differs between library
// implementations), so uniform and normal variates are derived here by fixed formulas: the same
// seed gives the same simulated data on every platform.

#include <cmath>
#include <cstdint>
#include <numbers>
#include <random>

namespace imucal::sim {

class Rng {
 public:
  explicit Rng(std::uint64_t seed) : engine_(seed) {}

  /// Derives an independent seed for a named sub-stream (motion, parameters, noise), so that
  /// fixing one part (e.g. the parameters from a truth file) leaves the others unchanged.
  static std::uint64_t substream(std::uint64_t seed, std::uint64_t salt) {
    std::uint64_t z = seed + 0x9E3779B97F4A7C15ull * (salt + 1);  // splitmix64 finaliser
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
  }

  /// Uniform in [0, 1) with 53 random bits.
  double uniform() { return static_cast<double>(engine_() >> 11) * 0x1.0p-53; }
  double uniform(double lo, double hi) { return lo + (hi - lo) * uniform(); }
  /// +1 or -1 with equal probability.
  double sign() { return (engine_() >> 63) != 0 ? 1.0 : -1.0; }
  /// Magnitude uniform in [lo, hi] with a random sign.
  double signed_magnitude(double lo, double hi) { return sign() * uniform(lo, hi); }

  /// Standard normal (Box-Muller; the second variate is kept for the next call).
  double normal() {
    if (has_spare_) {
      has_spare_ = false;
      return spare_;
    }
    double u1 = uniform();
    while (u1 <= 0.0) u1 = uniform();
    const double u2 = uniform();
    const double r = std::sqrt(-2.0 * std::log(u1));
    const double phi = 2.0 * std::numbers::pi * u2;
    spare_ = r * std::sin(phi);
    has_spare_ = true;
    return r * std::cos(phi);
  }

 private:
  std::mt19937_64 engine_;
  double spare_ = 0.0;
  bool has_spare_ = false;
};

}  // namespace imucal::sim
