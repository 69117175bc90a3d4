#pragma once
//! \file mesh_render.h
//! A small software rasteriser for the benchmark's pictures: triangle meshes drawn side by side
//! from one fixed viewpoint (orthographic, z-buffered, flat Lambert shading of each triangle,
//! two-sided), written as PNG with OpenCV.

#include <Eigen/Core>
#include <filesystem>
#include <string>
#include <vector>

#include "scanclean/core/triangle_mesh.h"

namespace scanclean::bench {

struct RenderPanel {
  const TriangleMesh* mesh = nullptr;
  std::string title;
};

struct RenderView {
  //! Rotation from world to camera (camera looks along -z, x right, y up).
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();
  Eigen::Vector3d light = Eigen::Vector3d(0.3, 0.5, 1.0);  //!< towards the light, camera frame
  int panel_size = 640;                                    //!< pixels, square panels
  //! The panel whose bounding box sets the common scale and centre.
  std::size_t frame_panel = 0;
};

//! Renders the panels left to right into one image and writes it (PNG, atomically). All panels
//! share the scale and centre of the frame panel's bounding box. \throw IoError.
void render_meshes_png(const std::vector<RenderPanel>& panels, const RenderView& view,
                       const std::filesystem::path& png);

}  // namespace scanclean::bench
