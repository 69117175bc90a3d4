// The filter's options (filter_options.h): the depth-frame preset differs from the defaults in
// exactly the two tests it turns off (the refit and the crease split are off in both), and
// validate() names the option in its message.

#include "scanclean/filter/filter_options.h"

#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "scanclean/core/errors.h"

namespace scanclean {
namespace {

TEST(FilterOptionsTest, DepthFramePresetTurnsOffTheScaleAndDisplacementTests) {
  const FilterOptions d = depth_frame_options(), base;
  EXPECT_EQ(d.scale_gamma, 0.0);
  EXPECT_EQ(d.displacement_sigma, 0.0);
  EXPECT_GT(base.scale_gamma, 0.0);
  EXPECT_GT(base.displacement_sigma, 0.0);
  EXPECT_EQ(d.refit_spread, 0.0);
  EXPECT_EQ(base.refit_spread, 0.0);  // off in the library's defaults as well
  EXPECT_EQ(d.crease_spread, 0.0);
  EXPECT_EQ(base.crease_spread, 0.0);  // off in the library's defaults as well
  FilterOptions same = d;
  same.scale_gamma = base.scale_gamma;
  same.displacement_sigma = base.displacement_sigma;
  same.refit_spread = base.refit_spread;
  same.crease_spread = base.crease_spread;
  EXPECT_EQ(same.k_h, base.k_h);
  EXPECT_EQ(same.noise_factor, base.noise_factor);
  EXPECT_EQ(same.outlier_sigma, base.outlier_sigma);
  EXPECT_EQ(same.likelihood_ratio, base.likelihood_ratio);
  EXPECT_EQ(same.tau, base.tau);
  EXPECT_NO_THROW(validate(d));
}

TEST(FilterOptionsTest, ValidateNamesTheOptionAndTheRange) {
  FilterOptions o;
  o.k_h = 1;
  try {
    validate(o);
    ADD_FAILURE() << "no exception";
  } catch (const OptionError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("k_h"), std::string::npos) << m;
    EXPECT_NE(m.find("[2, 1000]"), std::string::npos) << m;
  }
}

TEST(FilterOptionsTest, TheCreaseSpreadIsCheckedLikeTheRefitSpread) {
  FilterOptions o;
  for (const double bad : {-0.5, 101.0, std::nan("")}) {
    o.crease_spread = bad;
    try {
      validate(o);
      ADD_FAILURE() << "no exception for " << bad;
    } catch (const OptionError& e) {
      const std::string m = e.what();
      EXPECT_NE(m.find("crease_spread"), std::string::npos) << m;
      EXPECT_NE(m.find("[0, 100]"), std::string::npos) << m;
    }
  }
  o.crease_spread = 0;
  EXPECT_NO_THROW(validate(o));
}

}  // namespace
}  // namespace scanclean
