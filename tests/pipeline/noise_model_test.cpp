#include "scanclean/pipeline/noise_model.h"

#include <gtest/gtest.h>

#include <cmath>

namespace scanclean {
namespace {

constexpr double kDeg = M_PI / 180.0;

// Oracles: the values docs/SENSORS.md §4 lists, computed from the published formulas.
TEST(NoiseModelTest, NguyenAxialSigmaMatchesPublishedTable) {
  EXPECT_NEAR(nguyen_axial_sigma_m(1.0, 0.0), 0.0019, 0.00005);
  EXPECT_NEAR(nguyen_axial_sigma_m(1.0, 40 * kDeg), 0.0019, 0.0001);
  EXPECT_NEAR(nguyen_axial_sigma_m(1.0, 70 * kDeg), 0.0031, 0.0001);
  EXPECT_NEAR(nguyen_axial_sigma_m(2.0, 0.0), 0.0061, 0.0001);
  EXPECT_NEAR(nguyen_axial_sigma_m(2.0, 70 * kDeg), 0.0069, 0.0001);
  EXPECT_NEAR(nguyen_axial_sigma_m(3.0, 0.0), 0.014, 0.0005);
  EXPECT_NEAR(nguyen_axial_sigma_m(3.0, 70 * kDeg), 0.015, 0.0005);
  // Near-grazing angles stay finite.
  EXPECT_TRUE(std::isfinite(nguyen_axial_sigma_m(1.0, M_PI / 2)));
}

TEST(NoiseModelTest, QuantisationStepOfTypicalPs1080) {
  EXPECT_NEAR(ps1080_quantisation_step_m(1.0, std::nullopt), 0.0029, 0.0001);
  EXPECT_NEAR(ps1080_quantisation_step_m(2.0, std::nullopt), 0.0116, 0.0004);
  EXPECT_NEAR(ps1080_quantisation_step_m(3.0, std::nullopt), 0.026, 0.0005);
  EXPECT_NEAR(ps1080_quantisation_step_m(5.0, std::nullopt), 0.072, 0.001);
  // Device constants are used when complete: a doubled baseline halves the step.
  Ps1080Params p{120.0, 0.1042, 15.0, 4.0};
  EXPECT_NEAR(ps1080_quantisation_step_m(2.0, p), ps1080_quantisation_step_m(2.0, std::nullopt) / 2,
              1e-12);
  Ps1080Params incomplete{120.0, 0.1042, 0.0, 4.0};
  EXPECT_EQ(ps1080_quantisation_step_m(2.0, incomplete),
            ps1080_quantisation_step_m(2.0, std::nullopt));
}

TEST(NoiseModelTest, WeightIsOneAtReferenceAndFallsWithDepthAndAngle) {
  EXPECT_DOUBLE_EQ(nguyen_weight(0.8, 0.0, std::nullopt), 1.0);
  EXPECT_DOUBLE_EQ(nguyen_weight(0.6, 0.0, std::nullopt), 1.0);  // clamped
  double prev = 1.0;
  for (double z = 1.0; z <= 5.0; z += 0.5) {
    const double w = nguyen_weight(z, 0.0, std::nullopt);
    EXPECT_LT(w, prev);
    EXPECT_GT(w, 0.0);
    prev = w;
  }
  prev = 1.1;
  for (double deg = 0; deg < 89; deg += 10) {
    const double w = nguyen_weight(1.5, deg * kDeg, std::nullopt);
    EXPECT_LT(w, prev);
    prev = w;
  }
  const double s = depth_sigma_m(2.0, 0.0, std::nullopt);
  const double ref = depth_sigma_m(0.8, 0.0, std::nullopt);
  EXPECT_NEAR(nguyen_weight(2.0, 0.0, std::nullopt), (ref / s) * (ref / s), 1e-15);
}

}  // namespace
}  // namespace scanclean
