// Structured light on synthetic captures rendered through a known camera-projector calibration
// (sl_fixtures.h): decoding against the true projector pixels, triangulation against the true
// surfaces, shadows, the fast decoder against OpenCV's getProjPixel, and the RangeSource.

#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdio>

#include "scanclean/drivers/sl_capture.h"
#include "scanclean/drivers/sl_decode.h"
#include "scanclean/drivers/sl_triangulate.h"
#include "scanclean/drivers/structured_light_source.h"
#include "sl_fixtures.h"
#include "support/data_paths.h"

namespace scanclean {
namespace {

struct Fixture {
  test::SlScene scene;
  SlCalibration calib = test::make_sl_calibration();
  test::SlRendered rendered;
  std::filesystem::path folder;
  SlCaptureInfo info;
  SlCapture capture;
};

// Rendered once per test binary (the rendering dominates the suite's time).
const Fixture& fixture() {
  static const Fixture f = [] {
    Fixture x;
    x.rendered = test::render_sl_capture(x.calib, x.scene);
    x.folder = test::make_temp_dir("sl_synthetic") / "capture";
    test::write_sl_capture(x.folder, x.calib, x.rendered.images);
    x.info = describe_sl_capture(x.folder);
    x.capture = SlCapture::load(x.info);
    return x;
  }();
  return f;
}

TEST(SlSyntheticTest, CaptureFolderIsDescribed) {
  const Fixture& f = fixture();
  EXPECT_TRUE(is_structured_light_capture(f.folder));
  EXPECT_EQ(f.info.layout, "scanclean");
  EXPECT_EQ(f.info.graycode.column_bits, 10);  // ceil(log2 800)
  EXPECT_EQ(f.info.graycode.row_bits, 10);     // ceil(log2 600)
  EXPECT_EQ(f.info.images.size(), 42u);
  EXPECT_EQ(f.info.white_index, 40);
  EXPECT_EQ(f.info.black_index, 41);
  EXPECT_EQ(f.info.camera_serial, "synthetic-0");
  EXPECT_EQ(f.info.calibration.filename(), "calib.yml");
  EXPECT_EQ(f.capture.width(), 640);
  EXPECT_EQ(f.capture.height(), 480);
  EXPECT_EQ(f.capture.bit_depth(), 8);
}

TEST(SlSyntheticTest, DecodingMatchesTrueProjectorPixels) {
  const Fixture& f = fixture();
  const SlDecoded d = decode_graycode(f.capture, {});
  const auto& t = f.rendered.truth;
  std::size_t away = 0, exact = 0, valid_away = 0, lit = 0, lit_valid = 0;
  for (int v = 0; v < t.lit.height; ++v)
    for (int u = 0; u < t.lit.width; ++u) {
      if (!t.lit(u, v)) continue;
      ++lit;
      lit_valid += d.status(u, v) == 0;
      if (t.edge_distance_px(u, v) < 0.5f) continue;
      ++away;
      valid_away += d.status(u, v) == 0;
      exact += d.column(u, v) == std::lround(t.proj(u, v).x()) &&
               d.row(u, v) == std::lround(t.proj(u, v).y());
    }
  std::printf("lit %zu, valid among lit %.2f %%; away from stripe edges %zu: exact %.3f %%\n", lit,
              100.0 * lit_valid / lit, away, 100.0 * exact / away);
  ASSERT_GT(away, 10000u);  // enough pixels for the share to mean something
  EXPECT_GE(static_cast<double>(exact) / away, 0.99);
  EXPECT_GE(static_cast<double>(valid_away) / away, 0.99);
  // Near stripe edges blur and pixel area mix a projector pixel with its neighbour: some bit
  // then falls below the white threshold and the pixel is (rightly) refused.
  EXPECT_GE(static_cast<double>(lit_valid) / lit, 0.5);
}

TEST(SlSyntheticTest, ShadowedPixelsAreInvalidWithZeroConfidence) {
  const Fixture& f = fixture();
  const SlDecoded d = decode_graycode(f.capture, {});
  const auto& t = f.rendered.truth;
  std::size_t shadow = 0, shadow_invalid = 0, on_plane_shadow = 0;
  double lit_conf = 0;  // pixels away from stripe edges
  std::size_t lit_n = 0;
  for (int v = 2; v + 2 < t.lit.height; ++v)
    for (int u = 2; u + 2 < t.lit.width; ++u) {
      // Deep inside a shadow (2 px from its border: blur reaches about 2 px).
      bool deep = true;
      for (int dv = -2; dv <= 2; ++dv)
        for (int du = -2; du <= 2; ++du) deep = deep && !t.lit(u + du, v + dv);
      if (deep && t.surface(u, v) >= 0) {
        ++shadow;
        on_plane_shadow += t.surface(u, v) == 0;
        shadow_invalid += d.status(u, v) == static_cast<std::uint8_t>(SlPixelStatus::kShadow) &&
                          d.confidence(u, v) == 0.0f && d.column(u, v) == -1;
      }
      if (t.lit(u, v) && t.edge_distance_px(u, v) >= 0.5f && d.status(u, v) == 0) {
        lit_conf += d.confidence(u, v);
        ++lit_n;
      }
    }
  std::printf(
      "shadow pixels %zu (cast on the plane %zu), invalid %zu; mean confidence away from "
      "stripe edges %.3f\n",
      shadow, on_plane_shadow, shadow_invalid, lit_conf / lit_n);
  ASSERT_GT(on_plane_shadow, 500u);  // the sphere's projector shadow is in view
  EXPECT_EQ(shadow_invalid, shadow);
  EXPECT_GT(lit_conf / lit_n, 0.5);
}

TEST(SlSyntheticTest, FastDecoderEqualsOpenCV) {
  const Fixture& f = fixture();
  SlDecodeOptions o;
  o.decoder = SlDecoder::kOpenCV;
  const SlDecoded ref = decode_graycode(f.capture, o);
  o.decoder = SlDecoder::kFast;
  o.threads = 1;
  const SlDecoded fast1 = decode_graycode(f.capture, o);
  o.threads = 0;
  const SlDecoded fast = decode_graycode(f.capture, o);
  std::printf("decode 640x480: opencv %.1f ms, fast %.2f ms (1 thread), %.2f ms (all cores)\n",
              ref.seconds * 1e3, fast1.seconds * 1e3, fast.seconds * 1e3);
  ASSERT_GT(ref.valid, 100000u);
  EXPECT_EQ(ref.valid, fast.valid);
  EXPECT_EQ(ref.lit, fast.lit);
  std::size_t differ = 0;
  for (std::size_t i = 0; i < ref.status.size(); ++i) {
    differ += ref.status.data[i] != fast.status.data[i] ||
              ref.column.data[i] != fast.column.data[i] || ref.row.data[i] != fast.row.data[i] ||
              ref.confidence.data[i] != fast.confidence.data[i];
  }
  EXPECT_EQ(differ, 0u);
  EXPECT_EQ(fast.column.data, fast1.column.data);  // any thread count, same result
  EXPECT_EQ(fast.row.data, fast1.row.data);
}

TEST(SlSyntheticTest, TriangulatedPointsLieOnTheTrueSurfaces) {
  const Fixture& f = fixture();
  const SlDecoded d = decode_graycode(f.capture, {});
  const SlTriangulator tri(f.calib);
  SlTriangulationStats st;
  const RangeFrame frame = tri.triangulate(d, {}, &st);
  const auto& t = f.rendered.truth;
  // Interior pixels: 5x5 neighbourhood on one surface and lit (at depth discontinuities a pixel
  // mixes two surfaces; those "flying pixels" are the downstream filter's job).
  auto interior = [&](int u, int v) {
    if (u < 2 || v < 2 || u + 2 >= t.lit.width || v + 2 >= t.lit.height) return false;
    for (int dv = -2; dv <= 2; ++dv)
      for (int du = -2; du <= 2; ++du)
        if (t.surface(u + du, v + dv) != t.surface(u, v) || !t.lit(u + du, v + dv)) return false;
    return true;
  };
  double sum2[2] = {0, 0}, all2 = 0;
  std::size_t n[2] = {0, 0}, all = 0;
  std::size_t wrong_surface = 0;
  for (int v = 0; v < frame.height(); ++v)
    for (int u = 0; u < frame.width(); ++u) {
      const Eigen::Vector3f p = (*frame.points)(u, v);
      if (!p.allFinite()) {
        EXPECT_EQ(frame.depth(u, v), 0);
        EXPECT_EQ((*frame.confidence)(u, v), 0.0f);
        continue;
      }
      const int s = t.surface(u, v);
      if (s < 0) {
        ++wrong_surface;
        continue;
      }
      const double e = test::sl_surface_distance(f.scene, s, p.cast<double>() * 1000.0);
      all2 += e * e;
      ++all;
      if (interior(u, v)) {
        sum2[s] += e * e;
        ++n[s];
      }
      EXPECT_NEAR(frame.depth(u, v) * frame.depth_unit_m, p.z(), 0.6e-4);
      EXPECT_GT((*frame.confidence)(u, v), 0.0f);
    }
  const double rms_plane = std::sqrt(sum2[0] / n[0]), rms_sphere = std::sqrt(sum2[1] / n[1]);
  std::printf(
      "points %zu, RMS to the true surface: all %.3f mm; interior: plane %.3f mm (%zu), "
      "sphere %.3f mm (%zu); rejected by reprojection %zu, mean reprojection %.3f px\n",
      st.points, std::sqrt(all2 / all), rms_plane, n[0], rms_sphere, n[1], st.rejected_reprojection,
      st.mean_reprojection_px);
  EXPECT_EQ(wrong_surface, 0u);
  ASSERT_GT(n[0], 100000u);
  ASSERT_GT(n[1], 5000u);
  EXPECT_LT(rms_plane, 0.5);
  EXPECT_LT(rms_sphere, 0.5);
  EXPECT_EQ(frame.K.fx, f.calib.camera.fx);
  EXPECT_EQ(frame.K.dist, f.calib.camera.dist);
}

TEST(SlSyntheticTest, SourceDeliversOneFramePerCapture) {
  const Fixture& f = fixture();
  // A session folder of two captures sharing the calibration in the parent folder.
  const auto session = test::make_temp_dir("sl_session");
  for (const char* name : {"a", "b"}) {
    std::filesystem::create_directories(session / name / "img");
    std::filesystem::copy_file(f.folder / "capture.json", session / name / "capture.json");
    for (const auto& img : f.info.images)
      std::filesystem::copy_file(img, session / name / "img" / img.filename());
  }
  std::filesystem::copy_file(f.folder / "calib.yml", session / "calib.yml");
  EXPECT_FALSE(is_structured_light_capture(session));
  auto src = make_structured_light_source(session);
  src->open();
  const SourceInfo info = src->info();
  EXPECT_EQ(info.kind, "structured-light");
  EXPECT_EQ(info.noise_model, "structured-light");
  ASSERT_TRUE(info.frame_count.has_value());
  EXPECT_EQ(*info.frame_count, 2u);
  EXPECT_EQ(info.K.width, 640);
  RangeFrame a, b, c;
  ASSERT_EQ(src->next(a, std::chrono::milliseconds(0)), ReadStatus::kOk) << src->last_error();
  ASSERT_EQ(src->next(b, std::chrono::milliseconds(0)), ReadStatus::kOk) << src->last_error();
  EXPECT_EQ(src->next(c, std::chrono::milliseconds(0)), ReadStatus::kEndOfStream);
  EXPECT_EQ(a.index, 0u);
  EXPECT_EQ(b.index, 1u);
  ASSERT_TRUE(a.points && b.points && a.confidence);
  std::size_t same = 0, valid = 0;
  for (std::size_t i = 0; i < a.points->size(); ++i) {
    if (!a.points->data[i].allFinite()) continue;
    ++valid;
    same += a.points->data[i] == b.points->data[i];
  }
  EXPECT_GT(valid, 100000u);
  EXPECT_EQ(same, valid);  // identical images give identical frames
}

}  // namespace
}  // namespace scanclean
