#pragma once
//! \file point_cloud.h
//! The point set every module exchanges. Struct of arrays: positions are always present; every
//! other per-point array is either empty (absent) or exactly size() long.

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace scanclean {

//! Organized layout (a range image): rows x cols cells, each holding a point index or -1.
//! Used for PLY range_grid, organized PCD (width x height) and depth frames.
struct OrganizedGrid {
  int rows = 0;
  int cols = 0;
  std::vector<std::int32_t> index;  //!< rows*cols entries, row-major; -1 = empty cell

  bool empty() const { return rows == 0 || cols == 0; }
  std::int32_t at(int row, int col) const {
    return index[static_cast<std::size_t>(row) * cols + col];
  }
};

//! Storage type of a named per-point attribute, as it is written to files.
enum class AttributeType : std::uint8_t { kUInt8, kInt32, kUInt32, kFloat32, kFloat64 };

//! A named per-point scalar (e.g. the filter's "likelihood", "iterations", "flags").
//! Values are held as double, which represents every value of every AttributeType exactly.
struct Attribute {
  std::string name;
  AttributeType type = AttributeType::kFloat32;
  std::vector<double> values;
};

//! A point cloud. Units: metres unless a reader states otherwise (PLY/PCD carry no unit; the
//! Stanford and PCL data are in metres).
struct PointCloud {
  std::vector<Eigen::Vector3d> positions;  //!< always present
  std::vector<Eigen::Vector3f> normals;    //!< unit, oriented if known; empty = none
  std::vector<float> confidences;          //!< in [0, 1] (filter weights w_i); empty = none
  std::vector<float> intensities;          //!< scanner intensity; empty = none
  std::vector<std::array<std::uint8_t, 4>> colors;  //!< RGBA; empty = none
  std::vector<Attribute> attributes;                //!< further named per-point values
  OrganizedGrid grid;                               //!< empty unless organized

  std::size_t size() const { return positions.size(); }
  bool empty() const { return positions.empty(); }
  bool has_normals() const { return !normals.empty(); }
  bool has_confidences() const { return !confidences.empty(); }
  bool has_intensities() const { return !intensities.empty(); }
  bool has_colors() const { return !colors.empty(); }

  //! The attribute with this name, or nullptr.
  const Attribute* find_attribute(const std::string& name) const;
  Attribute* find_attribute(const std::string& name);
  //! Adds (or replaces) an attribute; values.size() must equal size().
  Attribute& set_attribute(std::string name, AttributeType type, std::vector<double> values);

  //! Throws std::logic_error if an optional array or the grid is inconsistent with size().
  void check_consistent() const;
};

//! The points with the given indices (in that order), with every per-point array. The grid is
//! kept, remapped (cells of dropped points become -1), only if the grid was present.
PointCloud select(const PointCloud& cloud, const std::vector<std::size_t>& indices);

//! Appends src to dst. Optional arrays present in only one of them are filled with defaults
//! (normal 0, confidence 1, intensity 0, colour white); attributes are matched by name. The
//! merged cloud is unorganized.
void append(PointCloud& dst, const PointCloud& src);

//! Applies a rigid transform to positions and normals.
void transform(PointCloud& cloud, const Eigen::Isometry3d& pose);

//! Axis-aligned bounding box of the positions (empty box for an empty cloud).
Eigen::AlignedBox3d bounding_box(const PointCloud& cloud);

}  // namespace scanclean
