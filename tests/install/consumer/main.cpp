// Filters a small synthetic cloud through an installed scanclean: a noisy plane (seeded) plus a
// few outliers far from it. Exits 0 only if the filter made the plane flatter, removed the far
// outliers and the result could be written and read back.
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <random>

#include "scanclean/filter/robust_filter.h"
#include "scanclean/io/point_cloud_io.h"

int main(int argc, char** argv) {
  const std::filesystem::path out = argc > 1 ? argv[1] : "consumer_clean.ply";
  std::mt19937 rng(42);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::normal_distribution<double> noise(0.0, 0.002);
  scanclean::PointCloud cloud;
  // One statement per draw: the order of a call's arguments is the compiler's choice.
  for (int i = 0; i < 5000; ++i) {
    const double z = noise(rng), y = u(rng), x = u(rng);
    cloud.positions.emplace_back(x, y, z);
  }
  for (int i = 0; i < 20; ++i) {
    const double z = 0.2 + u(rng), y = u(rng), x = u(rng);
    cloud.positions.emplace_back(x, y, z);
  }

  const scanclean::FilterResult r = scanclean::robust_filter(cloud);
  double rms_in = 0, rms_out = 0, max_out = 0;
  for (std::size_t i = 0; i < 5000; ++i) rms_in += cloud.positions[i].z() * cloud.positions[i].z();
  for (const auto& p : r.cloud.positions) {
    rms_out += p.z() * p.z();
    max_out = std::max(max_out, std::abs(p.z()));
  }
  rms_in = std::sqrt(rms_in / 5000);
  rms_out = std::sqrt(rms_out / static_cast<double>(r.cloud.size()));
  scanclean::write_point_cloud(out, r.cloud);
  const scanclean::PointCloud back = scanclean::read_point_cloud(out);
  std::printf(
      "consumer: %zu points in, %zu out, %zu removed; rms |z| %.5f -> %.5f m, max |z| "
      "%.5f m; h = %.5f m; %s: %zu points\n",
      cloud.size(), r.cloud.size(), r.stats.removed(), rms_in, rms_out, max_out, r.stats.h,
      out.string().c_str(), back.size());
  const bool ok = rms_out < 0.5 * rms_in && max_out < 0.1 && back.size() == r.cloud.size();
  if (!ok) std::fprintf(stderr, "consumer: FAILED\n");
  return ok ? 0 : 1;
}
