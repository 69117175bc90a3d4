// scanclean_gencloud: big, realistic, seeded test clouds for the scaling benchmark, streamed to
// disk (never held whole), and the comparison of two filter outputs.
//
//   scanclean_gencloud scene OUT.ply --points N [--seed S] [--noise M] [--outliers F]
//   scanclean_gencloud compare A.ply B.ply
//
// scene: a campaign of "sites" on a square grid of 4 m pitch, 100,000 points each (the last
// site takes the rest): a 4 m x 4 m floor patch and one object on it (a sphere, a torus, a box
// or an upright cylinder; its kind, size and place drawn from the site's own seed), sampled
// uniformly by area, with isotropic Gaussian noise (--noise, metres, default 0.005) and a share
// of uniform outliers in the site's 4 m x 4 m x 3 m volume (--outliers, default 0.02). Records:
// x y z (float), intensity (float, a smooth function of the position, plus noise) and `truth`
// (uchar: 0 surface sample, 1 outlier): the ground truth. Sites are generated in parallel,
// written in order: the same seed gives the same bytes.
//
// compare: two filter outputs (PLY with source_index) matched by source_index; prints the points
// in only one of them, the flags that differ, the positions that differ and the largest
// difference (metres). Exit 0 when identical (same points, flags, bit-identical positions),
// 1 otherwise.

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <string>
#include <unordered_map>
#include <vector>

#include "rng.h"
#include "scanclean/core/atomic_file.h"
#include "scanclean/io/ply.h"

namespace {

using scanclean::bench::Rng;

constexpr std::uint64_t kSitePoints = 100000;
constexpr double kPitch = 4.0;
constexpr std::size_t kRecord = 17;  // 3 float + float + uchar

struct Site {
  int kind = 0;  // 0 sphere, 1 torus, 2 box, 3 cylinder
  double cx = 0, cy = 0, size = 0;
};

void put_record(char* out, float x, float y, float z, float intensity, std::uint8_t truth) {
  std::memcpy(out, &x, 4);
  std::memcpy(out + 4, &y, 4);
  std::memcpy(out + 8, &z, 4);
  std::memcpy(out + 12, &intensity, 4);
  out[16] = static_cast<char>(truth);
}

// The records of site s (n points) into out.
void make_site(std::uint64_t seed, std::uint64_t s, std::uint64_t side, std::uint64_t n,
               double noise, double outliers, char* out) {
  Rng rng(seed * 0x9E3779B97F4A7C15ULL + s * 0xBF58476D1CE4E5B9ULL + 1);
  const double ox = static_cast<double>(s % side) * kPitch;
  const double oy = static_cast<double>(s / side) * kPitch;
  Site site;
  site.kind = static_cast<int>(rng.index(4));
  site.size = rng.uniform(0.4, 1.1);
  site.cx = ox + 2.0 + rng.uniform(-0.6, 0.6);
  site.cy = oy + 2.0 + rng.uniform(-0.6, 0.6);
  const double floor_area = kPitch * kPitch;
  const double r = site.size;
  double object_area = 0;
  switch (site.kind) {
    case 0:
      object_area = 2 * M_PI * r * r;
      break;  // upper half sphere
    case 1:
      object_area = 4 * M_PI * M_PI * r * (0.3 * r) / 2;
      break;  // upper half torus
    case 2:
      object_area = 4 * (2 * r) * r + (2 * r) * (2 * r);
      break;  // box, no bottom
    default:
      object_area = 2 * M_PI * (0.5 * r) * (2 * r);
      break;  // cylinder wall
  }
  const double p_floor = floor_area / (floor_area + object_area);
  for (std::uint64_t i = 0; i < n; ++i) {
    double x, y, z;
    std::uint8_t truth = 0;
    if (rng.uniform() < outliers) {
      x = ox + rng.uniform(0, kPitch);
      y = oy + rng.uniform(0, kPitch);
      z = rng.uniform(-0.5, 2.5);
      truth = 1;
    } else if (rng.uniform() < p_floor) {
      x = ox + rng.uniform(0, kPitch);
      y = oy + rng.uniform(0, kPitch);
      z = 0;
    } else {
      switch (site.kind) {
        case 0: {  // uniform on the upper half sphere: z uniform (Archimedes)
          const double zz = rng.uniform(0, 1), a = rng.uniform(0, 2 * M_PI);
          const double rr = std::sqrt(std::max(0.0, 1 - zz * zz));
          x = site.cx + r * rr * std::cos(a);
          y = site.cy + r * rr * std::sin(a);
          z = r * zz;
          break;
        }
        case 1: {  // torus of radii r and 0.3 r, upper half, area-uniform by rejection
          const double R = r, q = 0.3 * r;
          double u, v;
          do {
            u = rng.uniform(0, 2 * M_PI);
            v = rng.uniform(0, M_PI);
          } while (rng.uniform() * (R + q) > R + q * std::cos(v));
          x = site.cx + (R + q * std::cos(v)) * std::cos(u);
          y = site.cy + (R + q * std::cos(v)) * std::sin(u);
          z = q * std::sin(v);
          break;
        }
        case 2: {  // box 2r x 2r x r: four walls and the top
          const double pick = rng.uniform(0, 12 * r * r);
          const double a = rng.uniform(-r, r), b = rng.uniform(0, r);
          if (pick < 4 * r * r) {
            x = site.cx + a;
            y = site.cy + rng.uniform(-r, r);
            z = r;
          } else {
            const int wall = static_cast<int>(rng.index(4));
            x = site.cx + (wall < 2 ? a : (wall == 2 ? -r : r));
            y = site.cy + (wall < 2 ? (wall == 0 ? -r : r) : a);
            z = b;
          }
          break;
        }
        default: {  // upright cylinder wall, radius r / 2, height 2 r
          const double a = rng.uniform(0, 2 * M_PI);
          x = site.cx + 0.5 * r * std::cos(a);
          y = site.cy + 0.5 * r * std::sin(a);
          z = rng.uniform(0, 2 * r);
          break;
        }
      }
    }
    if (!truth) {
      x += noise * rng.normal();
      y += noise * rng.normal();
      z += noise * rng.normal();
    }
    const double intensity = 0.5 + 0.25 * std::sin(x) * std::cos(y) + 0.02 * rng.normal();
    put_record(out + i * kRecord, static_cast<float>(x), static_cast<float>(y),
               static_cast<float>(z), static_cast<float>(intensity), truth);
  }
}

int scene(int argc, char** argv) {
  if (argc < 3) {
    std::fprintf(stderr,
                 "usage: scanclean_gencloud scene OUT.ply --points N [--seed S] "
                 "[--noise M] [--outliers F]\n");
    return 2;
  }
  const std::string out = argv[2];
  std::uint64_t points = 0, seed = 1;
  double noise = 0.005, outliers = 0.02;
  for (int i = 3; i + 1 < argc; i += 2) {
    const std::string k = argv[i], v = argv[i + 1];
    if (k == "--points")
      points = std::stoull(v);
    else if (k == "--seed")
      seed = std::stoull(v);
    else if (k == "--noise")
      noise = std::stod(v);
    else if (k == "--outliers")
      outliers = std::stod(v);
    else {
      std::fprintf(stderr, "scanclean_gencloud: unknown option %s\n", k.c_str());
      return 2;
    }
  }
  if (points == 0 || !(noise >= 0) || !(outliers >= 0 && outliers <= 1)) {
    std::fprintf(stderr, "scanclean_gencloud: --points > 0, --noise >= 0, --outliers in [0, 1]\n");
    return 2;
  }
  const std::uint64_t sites = (points + kSitePoints - 1) / kSitePoints;
  const auto side = static_cast<std::uint64_t>(std::ceil(std::sqrt(static_cast<double>(sites))));
  std::string header = "ply\nformat binary_little_endian 1.0\n";
  header += "comment scanclean_gencloud scene seed " + std::to_string(seed) + " noise " +
            std::to_string(noise) + " outliers " + std::to_string(outliers) + " (metres)\n";
  header += "element vertex " + std::to_string(points) + "\n";
  header +=
      "property float x\nproperty float y\nproperty float z\nproperty float intensity\n"
      "property uchar truth\nend_header\n";
  scanclean::write_file_atomically(out, [&](std::ostream& os) {
    os.write(header.data(), static_cast<std::streamsize>(header.size()));
    constexpr std::uint64_t kBatch = 32;  // sites generated in parallel, written in order
    std::vector<char> buf(kBatch * kSitePoints * kRecord);
    for (std::uint64_t s0 = 0; s0 < sites; s0 += kBatch) {
      const std::uint64_t s1 = std::min(sites, s0 + kBatch);
      tbb::parallel_for(s0, s1, [&](std::uint64_t s) {
        const std::uint64_t n = std::min(kSitePoints, points - s * kSitePoints);
        make_site(seed, s, side, n, noise, outliers, buf.data() + (s - s0) * kSitePoints * kRecord);
      });
      const std::uint64_t n = std::min(points, s1 * kSitePoints) - s0 * kSitePoints;
      os.write(buf.data(), static_cast<std::streamsize>(n * kRecord));
      std::fprintf(stderr, "\rscanclean_gencloud: %llu / %llu sites",
                   static_cast<unsigned long long>(s1), static_cast<unsigned long long>(sites));
    }
    std::fprintf(stderr, "\n");
  });
  std::printf(
      "wrote %s: %llu points, %llu sites on a %llu x %llu grid (%.0f m x %.0f m), %.2f GB\n",
      out.c_str(), static_cast<unsigned long long>(points), static_cast<unsigned long long>(sites),
      static_cast<unsigned long long>(side), static_cast<unsigned long long>(side), side * kPitch,
      side * kPitch, static_cast<double>(header.size() + points * kRecord) / 1e9);
  return 0;
}

int compare(int argc, char** argv) {
  if (argc != 4) {
    std::fprintf(stderr, "usage: scanclean_gencloud compare A.ply B.ply\n");
    return 2;
  }
  const scanclean::PointCloud a = scanclean::read_ply(argv[2]);
  const scanclean::PointCloud b = scanclean::read_ply(argv[3]);
  const auto* sa = a.find_attribute("source_index");
  const auto* sb = b.find_attribute("source_index");
  const auto* fa = a.find_attribute("flags");
  const auto* fb = b.find_attribute("flags");
  if (!sa || !sb) {
    std::fprintf(stderr, "compare: both files need a source_index attribute\n");
    return 2;
  }
  std::unordered_map<std::uint64_t, std::size_t> in_b;
  in_b.reserve(b.size());
  for (std::size_t k = 0; k < b.size(); ++k) in_b[static_cast<std::uint64_t>(sb->values[k])] = k;
  std::size_t only = 0, flags = 0, moved = 0, common = 0;
  double largest = 0;
  for (std::size_t k = 0; k < a.size(); ++k) {
    const auto it = in_b.find(static_cast<std::uint64_t>(sa->values[k]));
    if (it == in_b.end()) {
      ++only;
      continue;
    }
    ++common;
    const double d = (a.positions[k] - b.positions[it->second]).norm();
    largest = std::max(largest, d);
    moved += d > 0 ? 1 : 0;
    if (fa && fb) flags += fa->values[k] != fb->values[it->second] ? 1 : 0;
  }
  only += b.size() - common;
  std::printf(
      "points %zu / %zu, in one only %zu, flags differ %zu, positions differ %zu, "
      "largest difference %.3g m\n",
      a.size(), b.size(), only, flags, moved, largest);
  return only == 0 && flags == 0 && moved == 0 ? 0 : 1;
}

}  // namespace

int main(int argc, char** argv) {
  const std::string verb = argc > 1 ? argv[1] : "";
  try {
    if (verb == "scene") return scene(argc, argv);
    if (verb == "compare") return compare(argc, argv);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "scanclean_gencloud: error: %s\n", e.what());
    return 1;
  }
  std::fprintf(stderr,
               "usage: scanclean_gencloud scene OUT.ply --points N [--seed S] "
               "[--noise M] [--outliers F]\n       scanclean_gencloud compare A.ply B.ply\n");
  return 2;
}
