#include "scanclean/replay/recording_format.h"

#include <gtest/gtest.h>

#include <fstream>
#include <nlohmann/json.hpp>

#include "replay_fixtures.h"
#include "scanclean/core/errors.h"
#include "support/data_paths.h"

namespace scanclean {
namespace {

using nlohmann::json;

void expect_same(const SessionMetadata& a, const SessionMetadata& b) {
  EXPECT_EQ(a.format, b.format);
  EXPECT_EQ(a.device.kind, b.device.kind);
  EXPECT_EQ(a.device.vendor, b.device.vendor);
  EXPECT_EQ(a.device.name, b.device.name);
  EXPECT_EQ(a.device.uri, b.device.uri);
  EXPECT_EQ(a.device.usb, b.device.usb);
  EXPECT_EQ(a.device.serial, b.device.serial);
  EXPECT_EQ(a.device.firmware, b.device.firmware);
  EXPECT_EQ(a.width, b.width);
  EXPECT_EQ(a.height, b.height);
  EXPECT_EQ(a.unit_m, b.unit_m);  // exact: JSON numbers round-trip doubles
  EXPECT_EQ(a.K.fx, b.K.fx);
  EXPECT_EQ(a.K.fy, b.K.fy);
  EXPECT_EQ(a.K.cx, b.K.cx);
  EXPECT_EQ(a.K.cy, b.K.cy);
  EXPECT_EQ(a.K.dist, b.K.dist);
  EXPECT_EQ(a.K.source, b.K.source);
  EXPECT_EQ(a.noise_model, b.noise_model);
  ASSERT_EQ(a.ps1080.has_value(), b.ps1080.has_value());
  if (a.ps1080) {
    EXPECT_EQ(a.ps1080->zpd_mm, b.ps1080->zpd_mm);
    EXPECT_EQ(a.ps1080->zpps_mm, b.ps1080->zpps_mm);
    EXPECT_EQ(a.ps1080->lddis_cm, b.ps1080->lddis_cm);
    EXPECT_EQ(a.ps1080->param_coeff, b.ps1080->param_coeff);
  }
  EXPECT_EQ(a.registration, b.registration);
  ASSERT_EQ(a.extrinsics_depth_to_color.has_value(), b.extrinsics_depth_to_color.has_value());
  if (a.extrinsics_depth_to_color) {
    EXPECT_EQ(a.extrinsics_depth_to_color->R, b.extrinsics_depth_to_color->R);
    EXPECT_EQ(a.extrinsics_depth_to_color->T, b.extrinsics_depth_to_color->T);
  }
  EXPECT_EQ(a.created, b.created);
  EXPECT_EQ(a.finalized, b.finalized);
  EXPECT_EQ(a.frame_count, b.frame_count);
}

TEST(RecordingFormatTest, JsonRoundTripIsExact) {
  SessionMetadata s = test::fixture_session();
  s.K.fx = 570.3422047415297;  // a value with all 17 significant digits
  s.finalized = true;
  s.frame_count = 42;
  const std::string text = session_to_json(s);
  expect_same(s, session_from_json(text, "session.json"));
  // Optional parts absent stay absent.
  s.ps1080.reset();
  s.extrinsics_depth_to_color.reset();
  s.finalized = false;
  s.frame_count.reset();
  expect_same(s, session_from_json(session_to_json(s), "session.json"));
}

TEST(RecordingFormatTest, JsonHasTheDocumentedLayout) {
  const json j = json::parse(session_to_json(test::fixture_session()));
  EXPECT_EQ(j.at("format"), "scanclean-rec/1");
  EXPECT_EQ(j.at("device").at("usb"), "1d27:0601");
  EXPECT_EQ(j.at("depth").at("width"), 16);
  EXPECT_EQ(j.at("depth").at("height"), 12);
  EXPECT_EQ(j.at("depth").at("unit_m"), 0.0001);
  EXPECT_EQ(j.at("depth").at("invalid"), 0);
  EXPECT_EQ(j.at("intrinsics").at("dist").size(), 5u);
  EXPECT_EQ(j.at("intrinsics").at("source"), "calibration");
  EXPECT_EQ(j.at("noise_model").at("name"), "nguyen2012");
  EXPECT_EQ(j.at("ps1080").at("zpd_mm"), 120.0);
  EXPECT_EQ(j.at("registration"), "depth_to_color");
  EXPECT_EQ(j.at("finalized"), false);
  EXPECT_FALSE(j.contains("frame_count"));
}

//! Mutates a valid session JSON and expects an InputError whose message names the file and
//! contains `needle` (the field or the expectation).
void expect_rejected(const std::function<void(json&)>& mutate, const std::string& needle) {
  json j = json::parse(session_to_json(test::fixture_session()));
  mutate(j);
  try {
    session_from_json(j.dump(), "/rec/x/session.json");
    FAIL() << "accepted a session with " << needle;
  } catch (const InputError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("/rec/x/session.json"), std::string::npos) << msg;
    EXPECT_NE(msg.find(needle), std::string::npos) << msg;
  }
}

TEST(RecordingFormatTest, RejectsBadFieldsNamingFileAndField) {
  expect_rejected([](json& j) { j["format"] = "scanclean-rec/2"; }, "scanclean-rec/2");
  expect_rejected([](json& j) { j.erase("format"); }, "field format: missing");
  expect_rejected([](json& j) { j["depth"]["width"] = "640"; }, "field depth.width");
  expect_rejected([](json& j) { j["depth"]["height"] = -3; }, "field depth.height");
  expect_rejected([](json& j) { j["depth"]["unit_m"] = 0; }, "field depth.unit_m");
  expect_rejected([](json& j) { j["depth"]["invalid"] = 65535; }, "field depth.invalid");
  expect_rejected([](json& j) { j["intrinsics"]["fx"] = "525"; }, "field intrinsics.fx");
  expect_rejected(
      [](json& j) {
        j["intrinsics"]["dist"] = json::array({0, 0});
      },
      "field intrinsics.dist");
  expect_rejected([](json& j) { j["intrinsics"]["source"] = "guess"; }, "field intrinsics.source");
  expect_rejected([](json& j) { j["device"] = 7; }, "field device");
  expect_rejected([](json& j) { j["noise_model"]["name"] = "kinect"; }, "field noise_model.name");
  expect_rejected([](json& j) { j["ps1080"].erase("zpd_mm"); }, "field ps1080.zpd_mm");
  expect_rejected([](json& j) { j["finalized"] = "yes"; }, "field finalized");
  expect_rejected([](json& j) { j["finalized"] = true; }, "field frame_count");
  expect_rejected([](json& j) { j = json::array(); }, "expected a JSON object");
}

TEST(RecordingFormatTest, SyntaxErrorNamesByteOffset) {
  try {
    session_from_json("{\"format\": \"scanclean-rec/1\",, }", "s.json");
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("s.json: byte "), std::string::npos) << e.what();
  }
}

TEST(RecordingFormatTest, ReadSessionMissingFileIsInputError) {
  const auto dir = test::make_temp_dir("session_missing");
  try {
    read_session(dir);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find((dir / "session.json").string()), std::string::npos);
  }
  EXPECT_FALSE(is_recording_folder(dir));
  write_session(dir, test::fixture_session());
  EXPECT_TRUE(is_recording_folder(dir));
  expect_same(test::fixture_session(), read_session(dir));
  std::filesystem::remove_all(dir);
}

TEST(RecordingFormatTest, InfoAndSessionConvertBothWays) {
  SourceInfo info;
  info.uri = "openni2://";
  info.kind = "openni2";
  info.vendor = "PrimeSense";
  info.name = "PS1080";
  info.serial = "123";
  info.usb_id = "1d27:0601";
  info.firmware = "5.8";
  info.is_live = true;
  info.K = Intrinsics::from_fov(640, 480, 1.0226, 0.7966);
  info.depth_unit_m = 0.0001;
  info.noise_model = "nguyen2012";
  info.ps1080 = Ps1080Params{120, 0.1042, 7.5, 4};
  const SessionMetadata s = session_from_info(info, 640, 480);
  EXPECT_EQ(s.device.kind, "openni2");
  EXPECT_EQ(s.device.uri, "openni2://");
  EXPECT_EQ(s.device.usb, "1d27:0601");
  EXPECT_EQ(s.width, 640);
  EXPECT_EQ(s.K.fx, info.K.fx);
  EXPECT_EQ(s.unit_m, 0.0001);
  ASSERT_TRUE(s.ps1080);
  EXPECT_EQ(s.ps1080->zpps_mm, 0.1042);
  EXPECT_FALSE(s.finalized);

  const SourceInfo back = info_from_session(s, "/rec/a");
  EXPECT_EQ(back.uri, "/rec/a");
  EXPECT_EQ(back.kind, "recording");
  EXPECT_FALSE(back.is_live);
  EXPECT_EQ(back.vendor, "PrimeSense");
  EXPECT_EQ(back.serial, "123");
  EXPECT_EQ(back.usb_id, "1d27:0601");
  EXPECT_EQ(back.firmware, "5.8");
  EXPECT_EQ(back.K.fx, info.K.fx);
  EXPECT_EQ(back.K.width, 640);
  EXPECT_EQ(back.depth_unit_m, 0.0001);
  EXPECT_EQ(back.noise_model, "nguyen2012");
  EXPECT_FALSE(back.frame_count);
  EXPECT_THROW(session_from_info(info, 0, 480), OptionError);
}

}  // namespace
}  // namespace scanclean
