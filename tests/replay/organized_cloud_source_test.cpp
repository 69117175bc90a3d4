// Organized clouds as a range source (replay/organized_cloud_source.h): synthetic PCD
// sequences with known intrinsics and colours, the refusals, and the PCL grabber's real
// sequence (../shared/data/pcl_grabber_sequence/pcd, PROVENANCE.md section 4).
#include "scanclean/replay/organized_cloud_source.h"

#include <gtest/gtest.h>

#include <random>

#include "scanclean/core/errors.h"
#include "scanclean/io/point_cloud_io.h"
#include "support/data_paths.h"

namespace scanclean {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;

constexpr int kW = 40, kH = 30;
constexpr double kFx = 52.5, kFy = 51.0, kCx = 19.25, kCy = 14.5;

// A tilted plane seen by the pinhole camera above; cells with (u + v) % 7 == 0 are empty.
// Colour (u, v, seed) per cell.
PointCloud organized_plane(int seed, bool colour = true) {
  PointCloud c;
  c.grid.rows = kH;
  c.grid.cols = kW;
  c.grid.index.assign(static_cast<std::size_t>(kW) * kH, -1);
  for (int v = 0; v < kH; ++v)
    for (int u = 0; u < kW; ++u) {
      if ((u + v) % 7 == 0) continue;
      const double z = 1.0 + 0.01 * u + 0.02 * v + 0.001 * seed;
      c.grid.index[static_cast<std::size_t>(v) * kW + u] = static_cast<std::int32_t>(c.size());
      c.positions.emplace_back((u - kCx) / kFx * z, (v - kCy) / kFy * z, z);
      if (colour)
        c.colors.push_back({static_cast<std::uint8_t>(u), static_cast<std::uint8_t>(v),
                            static_cast<std::uint8_t>(seed), 255});
    }
  return c;
}

TEST(OrganizedCloudSourceTest, SequenceBecomesFramesWithFittedIntrinsicsAndColour) {
  const auto dir = test::make_temp_dir("organized_seq");
  // PCL grabber names: the timestamps come from them, the order too (natural order).
  const char* names[] = {"frame_20121214T142255.814212.pcd", "frame_20121214T142256.068683.pcd"};
  for (int k = 0; k < 2; ++k) write_point_cloud(dir / names[k], organized_plane(k));
  auto src = make_organized_cloud_source(dir);
  src->open();
  const SourceInfo info = src->info();
  EXPECT_EQ(info.kind, "organized-clouds");
  EXPECT_NEAR(info.K.fx, kFx, 1e-3);
  EXPECT_NEAR(info.K.fy, kFy, 1e-3);
  EXPECT_NEAR(info.K.cx, kCx, 1e-3);
  EXPECT_NEAR(info.K.cy, kCy, 1e-3);
  EXPECT_NE(info.name.find("with colour"), std::string::npos) << info.name;
  std::vector<RangeFrame> frames;
  RangeFrame f;
  while (src->next(f, 0ms) == ReadStatus::kOk) frames.push_back(f);
  ASSERT_EQ(frames.size(), 2u);
  EXPECT_EQ(frames[1].device_ts_us - frames[0].device_ts_us, 254471);
  for (int k = 0; k < 2; ++k) {
    const PointCloud ref = organized_plane(k);
    const RangeFrame& fr = frames[static_cast<std::size_t>(k)];
    ASSERT_TRUE(fr.points && fr.color);
    ASSERT_EQ(fr.width(), kW);
    ASSERT_EQ(fr.height(), kH);
    std::size_t finite = 0;
    for (int v = 0; v < kH; ++v)
      for (int u = 0; u < kW; ++u) {
        const std::int32_t idx = ref.grid.at(v, u);
        const Eigen::Vector3f& p = (*fr.points)(u, v);
        if (idx < 0) {
          EXPECT_FALSE(p.allFinite());
          continue;
        }
        ++finite;
        EXPECT_LT((p.cast<double>() - ref.positions[static_cast<std::size_t>(idx)]).norm(), 1e-6);
        const std::array<std::uint8_t, 3> rgb{static_cast<std::uint8_t>(u),
                                              static_cast<std::uint8_t>(v),
                                              static_cast<std::uint8_t>(k)};
        EXPECT_EQ((*fr.color)(u, v), rgb);
      }
    EXPECT_EQ(finite, ref.size());
  }
  fs::remove_all(dir);
}

TEST(OrganizedCloudSourceTest, CloudsThatAreNoRangeImageAreRefusedNamingTheFile) {
  const auto dir = test::make_temp_dir("organized_bad");
  // Unorganized.
  PointCloud flat = organized_plane(0);
  flat.grid = {};
  write_point_cloud(dir / "flat.pcd", flat);
  auto a = make_organized_cloud_source(dir / "flat.pcd");
  try {
    a->open();
    ADD_FAILURE() << "an unorganized cloud was accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("flat.pcd"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("not an organized cloud"), std::string::npos) << e.what();
  }
  // Organized, but the points are shuffled over the grid: not a pinhole range image.
  PointCloud shuffled = organized_plane(0, false);
  std::mt19937 rng(7);  // seeded
  std::shuffle(shuffled.positions.begin(), shuffled.positions.end(), rng);
  write_point_cloud(dir / "shuffled.pcd", shuffled);
  auto b = make_organized_cloud_source(dir / "shuffled.pcd");
  try {
    b->open();
    ADD_FAILURE() << "a shuffled grid was accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("shuffled.pcd"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("not a pinhole range image"), std::string::npos)
        << e.what();
  }
  // A second cloud of another size.
  const auto seq = dir / "seq";
  fs::create_directories(seq);
  write_point_cloud(seq / "a1.pcd", organized_plane(0));
  PointCloud small = organized_plane(1);
  small.grid.rows = 15;  // half the rows: the index no longer fits the first cloud's grid
  small.grid.index.resize(static_cast<std::size_t>(kW) * 15);
  std::int32_t kept = 0;
  for (auto i : small.grid.index) kept = std::max(kept, i + 1);
  small.positions.resize(static_cast<std::size_t>(kept));
  small.colors.resize(static_cast<std::size_t>(kept));
  write_point_cloud(seq / "a2.pcd", small);
  auto c = make_organized_cloud_source(seq);
  c->open();
  RangeFrame f;
  ASSERT_EQ(c->next(f, 0ms), ReadStatus::kOk);
  EXPECT_THROW(c->next(f, 0ms), InputError);
  EXPECT_THROW(make_organized_cloud_source(dir / "nothing_here"), InputError);
  fs::remove_all(dir);
}

TEST(OrganizedCloudSourceTest, PclGrabberSequenceGivesTheKinectIntrinsicsAndColour) {
  SCANCLEAN_REQUIRE_SHARED("pcl_grabber_sequence/pcd");
  auto src = make_organized_cloud_source(test::shared_data_dir() / "pcl_grabber_sequence/pcd");
  src->open();
  // The sequence's .xml (PROVENANCE.md): fx = fy = 525, cx = 320, cy = 240.
  EXPECT_NEAR(src->info().K.fx, 525, 0.01);
  EXPECT_NEAR(src->info().K.fy, 525, 0.01);
  EXPECT_NEAR(src->info().K.cx, 320, 0.01);
  EXPECT_NEAR(src->info().K.cy, 240, 0.01);
  RangeFrame f;
  ASSERT_EQ(src->next(f, 0ms), ReadStatus::kOk);
  ASSERT_TRUE(f.points && f.color);
  std::size_t finite = 0;
  for (const auto& p : f.points->data) finite += p.allFinite() ? 1 : 0;
  EXPECT_EQ(finite, 271575u);  // PROVENANCE.md: 271,575 finite of 307,200
  ASSERT_EQ(src->next(f, 0ms), ReadStatus::kOk);
  EXPECT_EQ(src->next(f, 0ms), ReadStatus::kEndOfStream);
}

}  // namespace
}  // namespace scanclean
