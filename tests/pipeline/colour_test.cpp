// Colour through the capture pipeline: a frame's registered colour image becomes the points'
// colours, and per-pixel fusion averages the colours of the samples it keeps (not of the rejected
// ones).

#include <gtest/gtest.h>

#include <array>
#include <optional>
#include <vector>

#include "scanclean/core/errors.h"
#include "scanclean/pipeline/accumulate.h"
#include "scanclean/pipeline/clean_window.h"
#include "scanclean/pipeline/frame_to_points.h"

#include "support/synthetic.h"

namespace scanclean {
namespace {

TEST(PipelineColourTest, PointsTakeTheirPixelsColourAndFusionAveragesIt) {
  SourceInfo info;
  FrameToPointsOptions o;
  o.edge_margin_px = 0;
  o.weights = false;
  const PointCloud a = frame_to_points(test::coloured_wall_frame(1000, 100), info, o);
  ASSERT_TRUE(a.has_colors());
  ASSERT_EQ(a.colors.size(), a.size());
  for (int v = 0; v < 6; ++v)
    for (int u = 0; u < 8; ++u) {
      const std::int32_t i = a.grid.at(v, u);
      ASSERT_GE(i, 0);
      const auto& c = a.colors[static_cast<std::size_t>(i)];
      EXPECT_EQ(c[0], 100);
      EXPECT_EQ(c[1], 10 * u);
      EXPECT_EQ(c[2], 10 * v);
      EXPECT_EQ(c[3], 255);
    }
  // Three frames: two at 1 m (red 100 and 200), one at 3 m (red 0), rejected by the median test.
  const PointCloud b = frame_to_points(test::coloured_wall_frame(1000, 200), info, o);
  const PointCloud far = frame_to_points(test::coloured_wall_frame(3000, 0), info, o);
  std::size_t rejected = 0;
  const std::optional<PointCloud> f = fuse_static_clouds({a, b, far}, {}, &rejected);
  ASSERT_TRUE(f.has_value());
  EXPECT_EQ(rejected, 48u);
  ASSERT_TRUE(f->has_colors());
  for (const auto& c : f->colors) EXPECT_EQ(c[0], 150);
}

// The window path fuses the depth images themselves (fuse_depth_frames): the fused pixel's colour
// is the mean of the colours of the samples kept, as for clouds.
TEST(PipelineColourTest, DepthFusionOfTheWindowAveragesTheKeptSamplesColours) {
  WindowOptions o;
  o.points.edge_margin_px = 0;
  o.points.weights = false;
  const std::vector<RangeFrame> frames = {test::coloured_wall_frame(1000, 101),
                                          test::coloured_wall_frame(1000, 200),
                                          test::coloured_wall_frame(3000, 0)};
  const WindowInput in = window_input(frames, SourceInfo{}, o);
  EXPECT_EQ(in.fusion_rejected, 48u);
  ASSERT_EQ(in.points_fused, 48u);
  ASSERT_TRUE(in.cloud.has_colors());
  for (int v = 0; v < 6; ++v)
    for (int u = 0; u < 8; ++u) {
      const std::int32_t i = in.cloud.grid.at(v, u);
      ASSERT_GE(i, 0);
      const auto& c = in.cloud.colors[static_cast<std::size_t>(i)];
      EXPECT_EQ(c[0], 151);  // (101 + 200) / 2 rounded; the 3 m sample's 0 is not in it
      EXPECT_EQ(c[1], 10 * u);
      EXPECT_EQ(c[2], 10 * v);
    }
  // Colour on only some frames: fused as clouds, which keep no colour then (no made-up colour).
  std::vector<RangeFrame> mixed = frames;
  mixed[2].color.reset();
  const WindowInput m = window_input(mixed, SourceInfo{}, o);
  EXPECT_EQ(m.points_fused, 48u);
  EXPECT_FALSE(m.cloud.has_colors());
}

TEST(PipelineColourTest, ColourImageOfAnotherSizeIsAnInputError) {
  RangeFrame f = test::coloured_wall_frame(1000, 1);
  f.color = Image<std::array<std::uint8_t, 3>>(4, 3);
  EXPECT_THROW(frame_to_points(f, SourceInfo{}, FrameToPointsOptions{}), InputError);
}

}  // namespace
}  // namespace scanclean
