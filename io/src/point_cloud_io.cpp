#include "scanclean/io/point_cloud_io.h"

#include <algorithm>
#include <cctype>

#include "scanclean/core/errors.h"

namespace scanclean {

void validate(const WriteOptions& options) {
  if (options.pcd_encoding != "ascii" && options.pcd_encoding != "binary" &&
      options.pcd_encoding != "binary_compressed")
    throw OptionError("pcd_encoding '" + options.pcd_encoding +
                      "' is not valid; expected ascii, binary or binary_compressed");
}

std::string point_cloud_format(const std::filesystem::path& path) {
  std::string ext = path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  if (ext == ".ply") return "ply";
  if (ext == ".pcd") return "pcd";
  if (ext == ".xyz" || ext == ".txt") return "xyz";
  return "";
}

PointCloud read_point_cloud(const std::filesystem::path& path, ReadReport* report,
                            const XyzOptions& xyz) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec))
    throw InputError(path.string(), "",
                     "is a folder; expected a point-cloud file (.ply .pcd .xyz .txt)");
  const std::string f = point_cloud_format(path);
  if (f == "ply") return read_ply(path, report);
  if (f == "pcd") return read_pcd(path, report);
  if (f == "xyz") return read_xyz(path, report, xyz);
  throw InputError(path.string(), "",
                   "unsupported file extension '" + path.extension().string() +
                       "'; expected .ply, .pcd, .xyz or .txt");
}

void write_point_cloud(const std::filesystem::path& path, const PointCloud& cloud,
                       const WriteOptions& options) {
  validate(options);
  const std::string f = point_cloud_format(path);
  if (f == "ply") return write_ply(path, cloud, options.ply_encoding, options.provenance);
  if (f == "pcd") return write_pcd(path, cloud, options.pcd_encoding, options.provenance);
  if (f == "xyz") return write_xyz(path, cloud);
  throw OptionError("output " + path.string() + ": unsupported file extension '" +
                    path.extension().string() + "'; expected .ply, .pcd, .xyz or .txt");
}

}  // namespace scanclean
