#include "scanclean/core/point_cloud.h"

#include <stdexcept>
#include <utility>

namespace scanclean {

const Attribute* PointCloud::find_attribute(const std::string& name) const {
  for (const auto& a : attributes)
    if (a.name == name) return &a;
  return nullptr;
}

Attribute* PointCloud::find_attribute(const std::string& name) {
  for (auto& a : attributes)
    if (a.name == name) return &a;
  return nullptr;
}

Attribute& PointCloud::set_attribute(std::string name, AttributeType type,
                                     std::vector<double> values) {
  if (values.size() != size())
    throw std::logic_error("attribute '" + name + "' has " + std::to_string(values.size()) +
                           " values for " + std::to_string(size()) + " points");
  if (Attribute* existing = find_attribute(name)) {
    existing->type = type;
    existing->values = std::move(values);
    return *existing;
  }
  attributes.push_back(Attribute{std::move(name), type, std::move(values)});
  return attributes.back();
}

void PointCloud::check_consistent() const {
  const std::size_t n = size();
  auto check = [n](std::size_t m, const char* what) {
    if (m != 0 && m != n)
      throw std::logic_error(std::string("point cloud: ") + what + " has " + std::to_string(m) +
                             " entries for " + std::to_string(n) + " points");
  };
  check(normals.size(), "normals");
  check(confidences.size(), "confidences");
  check(intensities.size(), "intensities");
  check(colors.size(), "colors");
  for (const auto& a : attributes)
    if (a.values.size() != n) check(a.values.size() == 0 ? 1 : a.values.size(), a.name.c_str());
  if (!grid.empty()) {
    if (grid.index.size() != static_cast<std::size_t>(grid.rows) * grid.cols)
      throw std::logic_error("point cloud: grid index size does not match rows*cols");
    for (auto idx : grid.index)
      if (idx < -1 || (idx >= 0 && static_cast<std::size_t>(idx) >= n))
        throw std::logic_error("point cloud: grid index out of range");
  }
}

template <class T>
static void select_into(const std::vector<T>& in, const std::vector<std::size_t>& idx,
                        std::vector<T>& out) {
  if (in.empty()) return;
  out.reserve(idx.size());
  for (auto i : idx) out.push_back(in[i]);
}

PointCloud select(const PointCloud& cloud, const std::vector<std::size_t>& indices) {
  PointCloud out;
  select_into(cloud.positions, indices, out.positions);
  select_into(cloud.normals, indices, out.normals);
  select_into(cloud.confidences, indices, out.confidences);
  select_into(cloud.intensities, indices, out.intensities);
  select_into(cloud.colors, indices, out.colors);
  for (const auto& a : cloud.attributes) {
    Attribute b{a.name, a.type, {}};
    select_into(a.values, indices, b.values);
    out.attributes.push_back(std::move(b));
  }
  if (!cloud.grid.empty()) {
    std::vector<std::int32_t> remap(cloud.size(), -1);
    for (std::size_t k = 0; k < indices.size(); ++k)
      remap[indices[k]] = static_cast<std::int32_t>(k);
    out.grid.rows = cloud.grid.rows;
    out.grid.cols = cloud.grid.cols;
    out.grid.index.resize(cloud.grid.index.size(), -1);
    for (std::size_t c = 0; c < cloud.grid.index.size(); ++c)
      if (cloud.grid.index[c] >= 0) out.grid.index[c] = remap[cloud.grid.index[c]];
  }
  return out;
}

template <class T>
static void append_array(std::vector<T>& dst, std::size_t dst_n, const std::vector<T>& src,
                         std::size_t src_n, const T& fill) {
  if (dst.empty() && src.empty()) return;
  if (dst.empty()) dst.assign(dst_n, fill);
  if (src.empty())
    dst.insert(dst.end(), src_n, fill);
  else
    dst.insert(dst.end(), src.begin(), src.end());
}

void append(PointCloud& dst, const PointCloud& src) {
  const std::size_t n0 = dst.size(), n1 = src.size();
  append_array(dst.normals, n0, src.normals, n1, Eigen::Vector3f::Zero().eval());
  append_array(dst.confidences, n0, src.confidences, n1, 1.0f);
  append_array(dst.intensities, n0, src.intensities, n1, 0.0f);
  append_array(dst.colors, n0, src.colors, n1, std::array<std::uint8_t, 4>{255, 255, 255, 255});
  for (const auto& a : src.attributes) {
    Attribute* d = dst.find_attribute(a.name);
    if (!d) {
      dst.attributes.push_back(Attribute{a.name, a.type, std::vector<double>(n0, 0.0)});
      d = &dst.attributes.back();
    }
    d->values.insert(d->values.end(), a.values.begin(), a.values.end());
  }
  for (auto& d : dst.attributes)
    if (d.values.size() < n0 + n1) d.values.resize(n0 + n1, 0.0);
  dst.positions.insert(dst.positions.end(), src.positions.begin(), src.positions.end());
  dst.grid = OrganizedGrid{};
}

void transform(PointCloud& cloud, const Eigen::Isometry3d& pose) {
  for (auto& p : cloud.positions) p = pose * p;
  const Eigen::Matrix3f r = pose.linear().cast<float>();
  for (auto& n : cloud.normals) n = r * n;
}

Eigen::AlignedBox3d bounding_box(const PointCloud& cloud) {
  Eigen::AlignedBox3d box;
  for (const auto& p : cloud.positions) box.extend(p);
  return box;
}

}  // namespace scanclean
