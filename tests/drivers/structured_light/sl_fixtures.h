#pragma once
// Synthetic structured-light captures for the sl tests: a known camera + projector calibration,
// a tilted plane with a sphere in front of it (the sphere casts a projector shadow onto the
// plane), textured albedo, ambient light, pixel-area integration, Gaussian blur and seeded
// noise. Every pattern image is the real GrayCodePattern::generate() output, sampled through
// the projector model.

#include <Eigen/Core>
#include <cstdint>
#include <filesystem>
#include <vector>

#include "scanclean/core/image.h"
#include "scanclean/drivers/sl_calibration.h"

namespace scanclean::test {

struct SlScene {
  // Surfaces, camera frame, millimetres.
  Eigen::Vector3d plane_normal{0.2, -0.1, -1.0};  // normalised in make_sl_scene
  Eigen::Vector3d plane_point{0, 0, 400};
  bool with_sphere = true;
  Eigen::Vector3d sphere_centre{-25, 15, 330};
  double sphere_radius = 35;
  // Rendering.
  double ambient = 20, gain = 200;  // gray levels: albedo * (ambient + gain * pattern / 255)
  double blur_sigma_px = 0.6;
  double noise_sigma = 2.0;
  std::uint64_t seed = 7;
  int supersample = 2;  // per axis: pixel-area integration
  // A printed chessboard on the plane instead of the smooth texture: (board_cols + 1) x
  // (board_rows + 1) squares centred on plane_point, rows along board_x_dir (projected into the
  // plane); albedo 0.9 / 0.35, 0.6 around the board.
  bool chessboard = false;
  int board_cols = 9, board_rows = 7;  // inner corners
  double square_mm = 20;
  Eigen::Vector3d board_x_dir{1, 0, 0};
};

//! Inner corners of the scene's chessboard (camera frame, mm), OpenCV order candidates: row-major
//! from the corner at (-cols/2, -rows/2) squares.
std::vector<Eigen::Vector3d> sl_board_corners_mm(const SlScene& scene);

//! Per camera pixel truth (at the pixel centre).
struct SlTruth {
  Image<std::int8_t> surface;   // -1 none, 0 plane, 1 sphere
  Image<std::uint8_t> lit;      // projector light reaches the point (not shadowed, in frustum)
  Image<Eigen::Vector2d> proj;  // continuous projector coordinates (pixel centres at integers)
  Image<float>
      edge_distance_px;  // camera px to the nearest projector pixel boundary / surface edge
};

//! Camera 640x480 (f 1000, mild distortion), projector 800x600 (f 800, mild distortion) 250 mm
//! to the right of the camera, turned toward the scene centre; units mm.
SlCalibration make_sl_calibration();

struct SlRendered {
  std::vector<Image<std::uint8_t>> images;  // generate() order, then white, then black
  SlTruth truth;
};

SlRendered render_sl_capture(const SlCalibration& calib, const SlScene& scene);

//! Writes a capture folder in the scanclean layout (capture.json, img/NNN.png, calib.yml).
void write_sl_capture(const std::filesystem::path& folder, const SlCalibration& calib,
                      const std::vector<Image<std::uint8_t>>& images);

//! Signed distance (mm) of a point to the scene's true surface `surface`.
double sl_surface_distance(const SlScene& scene, int surface, const Eigen::Vector3d& p_mm);

}  // namespace scanclean::test
