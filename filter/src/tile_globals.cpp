#include "tile_globals.h"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <stdexcept>
#include <unordered_map>
#include <utility>

#include "input_checks.h"
#include "neighbor_index.h"
#include "parallel.h"
#include "point_set.h"
#include "scanclean/core/errors.h"
#include "select.h"
#include "tile_exchange.h"
#include "tile_scale.h"

namespace scanclean::detail {
namespace {

// robust_filter's input checks (input_checks.h), made in the first pass so that the error names
// the record, before a grid casts a coordinate to a cell and before any tile reaches the sink.
void check_chunk(const PointCloud& c, const std::vector<std::uint64_t>& rec,
                 const FilterOptions& o) {
  const bool weights = o.use_confidences && c.has_confidences();
  if (weights && c.confidences.size() != c.size())
    throw InputError("tiled filter input",
                     rec.empty() ? "a chunk" : "the chunk from record " + std::to_string(rec[0]),
                     "one confidence per point");
  const InvalidPoint bad = first_invalid_point(c, weights);
  if (bad.index < c.size())
    throw InputError("tiled filter input", "record " + std::to_string(rec[bad.index]), bad.what);
}

// The samples of the automatic h: the records k N / M, k < M, as robust_filter samples them.
std::uint64_t sample_count(std::uint64_t records) {
  return std::min<std::uint64_t>(records, 10000);
}

// What the passes after the first derive from its box.
struct Frame {
  Eigen::Vector3d origin;  // the box centre, origin of the float coordinates (as robust_filter's)
  double diag = 0;         // the box diagonal
  // h where no distance is found: 1e-3 of the diagonal (1e-3 m for a box of one location)
  double fallback_h = 0;
  double whole = 0;  // a reach that holds every point from any point: 2 diag + fallback_h
};

// Pass 1: box, count, arrays present; returns the positions of the samples of the automatic h
// (the records k N / 10,000, as robust_filter samples them) that are valid, in record order.
std::vector<Eigen::Vector3d> first_pass(const TiledSource& src, const FilterOptions& o,
                                        std::array<std::uint64_t, 2> range, std::size_t chunk,
                                        const TileComm& comm, GlobalPasses& g) {
  TiledGlobals& gl = g.globals;
  ScratchColumns& cols = g.columns;
  const std::uint64_t M = sample_count(src.records);
  std::vector<std::uint64_t> sample_rec(M);
  for (std::uint64_t k = 0; k < M; ++k) sample_rec[k] = k * src.records / M;
  cols.attributes = src.attributes;
  Eigen::AlignedBox3d box;
  std::uint64_t n = 0;
  std::uint8_t has[4] = {0, 0, 0, 0};
  std::vector<Eigen::Vector3d> samples;
  std::size_t next = static_cast<std::size_t>(
      std::lower_bound(sample_rec.begin(), sample_rec.end(), range[0]) - sample_rec.begin());
  stream_records(src, range[0], range[1], chunk,
                 [&](const PointCloud& c, const std::vector<std::uint64_t>& rec) {
                   check_columns(c, cols);  // the announced attributes (the arrays are found here)
                   check_chunk(c, rec, o);
                   for (const auto& p : c.positions) box.extend(p);
                   n += c.size();
                   has[0] |= c.has_normals();
                   has[1] |= c.has_confidences();
                   has[2] |= c.has_intensities();
                   has[3] |= c.has_colors();
                   for (std::size_t i = 0; i < c.size(); ++i) {
                     while (next < sample_rec.size() && sample_rec[next] < rec[i]) ++next;
                     if (next < sample_rec.size() && sample_rec[next] == rec[i])
                       samples.push_back(c.positions[i]);
                   }
                 });
  MessageWriter mine;
  mine.put(box.min());
  mine.put(box.max());
  mine.put<std::uint64_t>(n);
  mine.bytes.append(reinterpret_cast<const char*>(has), 4);
  mine.put_vec(samples);
  std::vector<Eigen::Vector3d> sample_positions;
  for (const std::string& m : allgather(comm, mine.bytes)) {
    MessageReader r{m};
    const auto lo = r.get<Eigen::Vector3d>(), hi = r.get<Eigen::Vector3d>();
    if ((lo.array() <= hi.array()).all()) {
      gl.box.extend(lo);
      gl.box.extend(hi);
    }
    gl.points += r.get<std::uint64_t>();
    const auto h4 = r.get<std::array<std::uint8_t, 4>>();
    cols.normals |= h4[0] != 0;
    cols.confidences |= h4[1] != 0;
    cols.intensities |= h4[2] != 0;
    cols.colors |= h4[3] != 0;
    const std::vector<Eigen::Vector3d> theirs = r.get_vec<Eigen::Vector3d>();
    // In record order: the processes read ascending ranges.
    sample_positions.insert(sample_positions.end(), theirs.begin(), theirs.end());
  }
  return sample_positions;
}

// A map from the cells (of size R) around sample positions to the samples: each sample is
// listed in the 27 cells around its own, so that a point looks up its own cell only.
class SampleCells {
 public:
  SampleCells(float R, const std::vector<Eigen::Vector3f>& q,
              const std::vector<std::uint32_t>& which)
      : R_(R) {
    for (std::size_t k = 0; k < which.size(); ++k)
      for (int dz = -1; dz <= 1; ++dz)
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx)
            near_[key(q[which[k]], dx, dy, dz)].push_back(static_cast<std::uint32_t>(k));
  }
  // The entries (indices into `which`) of samples whose 27 cells hold p; null for none.
  const std::vector<std::uint32_t>* near(const Eigen::Vector3f& p) const {
    const auto it = near_.find(key(p, 0, 0, 0));
    return it == near_.end() ? nullptr : &it->second;
  }

 private:
  std::uint64_t key(const Eigen::Vector3f& p, int dx, int dy, int dz) const {
    const auto c = [&](int a, int d) {
      return static_cast<std::uint64_t>(static_cast<std::int64_t>(std::floor(p[a] / R_)) + d +
                                        (1 << 20)) &
             0x1fffff;
    };
    return c(0, dx) | (c(1, dy) << 21) | (c(2, dz) << 42);
  }
  float R_;
  std::unordered_map<std::uint64_t, std::vector<std::uint32_t>> near_;
};

// Pass 2: the histogram, and the K-th neighbour distances of the samples `qf` (their positions,
// float, relative to frame.origin; kAuto, kAdaptive) into `kth`; kAuto also the rough estimate
// (scale.h's r_est) into g.r_est.
void histogram_and_neighbours(const TiledSource& src, const FilterOptions& o,
                              std::array<std::uint64_t, 2> range, std::size_t chunk,
                              const TileComm& comm, const Frame& frame,
                              const std::vector<Eigen::Vector3f>& qf, std::vector<double>& kth,
                              GlobalPasses& g) {
  const TiledGlobals& gl = g.globals;
  const int K = o.scale == ScaleMode::kAdaptive ? o.k_adaptive : o.k_h;
  g.histogram.assign(g.grid.cells(), 0);
  kth.assign(qf.size(), 0.0);
  double reach = 0;
  if (o.scale != ScaleMode::kFixed && !qf.empty()) {
    // A first reach from the samples' own spacing: the 8th neighbour among the samples, scaled
    // to K neighbours among all points as on a surface; grown until every sample has K + 1.
    NeighborIndex sidx(qf, 0.0);
    std::vector<double> d8(qf.size());
    for (std::size_t k = 0; k < qf.size(); ++k) {
      std::vector<std::pair<float, std::uint32_t>> nn;
      sidx.knn(qf[k], 9, nn);
      d8[k] = nn.empty() ? 0.0 : std::sqrt(static_cast<double>(nn.back().first));
    }
    const double r8 = median_of(d8);
    reach = r8 *
            std::sqrt(static_cast<double>(K + 1) * static_cast<double>(qf.size()) /
                      (8.0 * static_cast<double>(gl.points))) *
            2.0;
    if (!(reach > 0)) reach = frame.fallback_h;
  }
  // Each pass takes the samples still short of K + 1 neighbours (sparse clutter) with a reach
  // three times the last one's; the others keep their distances.
  // kAuto also takes scale.h's rough estimate r_est, which sizes the in-memory run's first point
  // index (and so, when it is kept for the kernels, their grid order): the median distance of
  // the samples to their ks-th nearest among every sub_step-th point.
  const bool want_est = o.scale == ScaleMode::kAuto;
  const std::uint64_t kk = static_cast<std::uint64_t>(K) + 1;
  const std::uint64_t sub_step = std::clamp<std::uint64_t>(gl.points / (8 * kk), 1, 16);
  const std::size_t ks =
      static_cast<std::size_t>(std::max<std::uint64_t>(2, (kk + sub_step / 2) / sub_step));
  std::vector<double> est(want_est ? qf.size() : 0, -1.0);
  std::vector<std::uint8_t> kth_done(qf.size(), 0);
  bool hist_done = false;
  std::vector<std::uint32_t> active(o.scale != ScaleMode::kFixed ? qf.size() : 0);
  std::iota(active.begin(), active.end(), 0u);
  std::vector<std::uint64_t>& hist = g.histogram;
  while (true) {
    const bool need_kth = !active.empty();
    if (hist_done && !need_kth) break;
    std::vector<std::vector<float>> d2(active.size()), d2s(want_est ? active.size() : 0);
    const float R = static_cast<float>(reach);
    const SampleCells cells(R, qf, active);
    stream_records(src, range[0], range[1], chunk,
                   [&](const PointCloud& c, const std::vector<std::uint64_t>& rec) {
                     for (std::size_t i = 0; i < c.size(); ++i) {
                       const Eigen::Vector3d& p = c.positions[i];
                       if (!hist_done) ++hist[g.grid.flat(g.grid.cell_of(p))];
                       if (!need_kth) continue;
                       const Eigen::Vector3f pf = (p - frame.origin).cast<float>();
                       const std::vector<std::uint32_t>* near = cells.near(pf);
                       if (!near) continue;
                       for (std::uint32_t k : *near) {
                         // The same float arithmetic as the neighbour index's distance test.
                         const Eigen::Vector3f& q = qf[active[k]];
                         const float ex = pf.x() - q.x(), ey = pf.y() - q.y(), ez = pf.z() - q.z();
                         const float dd = ex * ex + ey * ey + ez * ez;
                         if (!(dd < R * R)) continue;
                         d2[k].push_back(dd);
                         if (want_est && rec[i] % sub_step == 0) d2s[k].push_back(dd);
                       }
                     }
                   });
    // Sum the histograms and join the distance lists of every process. A histogram travels as
    // its occupied cells (cell, count): a surface occupies a small part of the grid's cells,
    // and every process receives every process's message. Where the processes' occupied cells
    // together would outweigh the array (many processes, each reading records from all over the
    // scene), the arrays are summed instead (comm.sum): the same counts.
    if (comm.ranks > 1) {
      const bool as_arrays = !hist_done && sum_histograms_as_arrays(comm, hist);
      if (as_arrays) comm.sum(hist);
      const bool gather_hist = !hist_done && !as_arrays;
      MessageWriter mine;
      if (gather_hist) {
        std::vector<std::array<std::uint64_t, 2>> occupied;
        for (std::size_t i = 0; i < hist.size(); ++i)
          if (hist[i] > 0) occupied.push_back({i, hist[i]});
        mine.put_vec(occupied);
      }
      for (auto& v : d2) mine.put_vec(v);
      for (auto& v : d2s) mine.put_vec(v);
      std::vector<std::uint64_t> sum(gather_hist ? hist.size() : 0, 0);
      std::vector<std::vector<float>> joined(d2.size()), joined_s(d2s.size());
      for (const std::string& m : allgather(comm, mine.bytes)) {
        MessageReader r{m};
        if (gather_hist)
          for (const auto& [cell, n] : r.get_vec<std::array<std::uint64_t, 2>>()) {
            if (cell >= sum.size())
              throw std::logic_error("tiled filter: a histogram cell outside the grid");
            sum[cell] += n;
          }
        for (auto* all : {&joined, &joined_s})
          for (auto& v : *all) {
            const auto part = r.get_vec<float>();
            v.insert(v.end(), part.begin(), part.end());
          }
      }
      if (gather_hist) hist = std::move(sum);
      d2 = std::move(joined);
      d2s = std::move(joined_s);
    }
    hist_done = true;
    const bool all_within = reach >= frame.whole;
    std::vector<std::uint32_t> still;
    for (std::size_t k = 0; k < active.size(); ++k) {
      const std::uint32_t a = active[k];
      if (!kth_done[a]) {
        kth[a] = kth_distance(d2[k], K, R, all_within);
        kth_done[a] = kth[a] >= 0;
      }
      if (want_est && est[a] < 0) {
        // As a k-d tree's ks nearest: the ks-th smallest distance, or the largest when fewer.
        auto& v = d2s[k];
        if (v.size() >= ks)
          est[a] =
              std::sqrt(static_cast<double>(kth_smallest_below(v.data(), v.size(), ks - 1, R * R)));
        else if (all_within)
          est[a] = v.empty()
                       ? 0.0
                       : std::sqrt(static_cast<double>(*std::max_element(v.begin(), v.end())));
      }
      if (!kth_done[a] || (want_est && est[a] < 0)) still.push_back(a);
    }
    active = std::move(still);
    reach = std::min(reach * 3.0, frame.whole);
  }
  if (want_est) {
    g.r_est = median_of(est);
    if (!(g.r_est > 0)) g.r_est = frame.fallback_h;
  }
}

// Pass 3 (kAuto): the neighbourhoods of every 4th sample (at 4,000 samples and more), gathered
// from every process: the noise fixed point and the scale test on them, as scale.h does on the
// whole cloud; repeated with a wider radius while it reached farther than the points gathered.
void noise_and_scale(const TiledSource& src, const FilterOptions& o,
                     std::array<std::uint64_t, 2> range, std::size_t chunk, const TileComm& comm,
                     const Frame& frame, const std::vector<Eigen::Vector3f>& qf, GlobalPasses& g) {
  TiledGlobals& gl = g.globals;
  const bool use_w = o.use_confidences && g.columns.confidences;
  const bool use_v = o.use_sensor_normals && g.columns.normals;
  const std::size_t step = sample_count(src.records) >= 4000 ? 4 : 1;
  std::vector<std::uint32_t> qs;  // indices into qf
  for (std::size_t k = 0; k < qf.size(); k += step) qs.push_back(static_cast<std::uint32_t>(k));
  double R = 3.0 * gl.h0;
  for (int attempt = 0; attempt < 6; ++attempt) {
    const float Rf = static_cast<float>(R);
    const SampleCells cells(Rf, qf, qs);
    MessageWriter mine;
    stream_records(src, range[0], range[1], chunk,
                   [&](const PointCloud& c, const std::vector<std::uint64_t>&) {
                     for (std::size_t i = 0; i < c.size(); ++i) {
                       const Eigen::Vector3f pf = (c.positions[i] - frame.origin).cast<float>();
                       const std::vector<std::uint32_t>* near = cells.near(pf);
                       if (!near) continue;
                       bool hit = false;
                       for (std::uint32_t s : *near)
                         if ((pf - qf[qs[s]]).squaredNorm() < Rf * Rf * 1.0001f) {
                           hit = true;
                           break;
                         }
                       if (!hit) continue;
                       mine.put(c.positions[i]);
                       mine.put(c.has_normals() ? c.normals[i] : Eigen::Vector3f::Zero().eval());
                       mine.put<float>(c.has_confidences() ? c.confidences[i] : 1.0f);
                     }
                   });
    PointSet gathered;
    gathered.v_orients_only = o.normals_orient_only;
    for (const std::string& m : allgather(comm, mine.bytes)) {
      MessageReader r{m};
      while (!r.done()) {
        gathered.p.push_back(r.get<Eigen::Vector3d>() - frame.origin);
        const auto v = r.get<Eigen::Vector3f>();
        const float w = r.get<float>();
        if (use_v) {
          const float len = v.norm();
          gathered.v.push_back((std::isfinite(len) && len > 1e-6f) ? Eigen::Vector3f(v / len)
                                                                   : Eigen::Vector3f::Zero());
        }
        if (use_w) gathered.w.push_back(w);
      }
    }
    // The samples among the gathered points (each sample is there: its own distance is 0).
    std::vector<Eigen::Vector3f> gf(gathered.p.size());
    for (std::size_t i = 0; i < gathered.p.size(); ++i) gf[i] = gathered.p[i].cast<float>();
    std::vector<std::size_t> in_g;
    {
      NeighborIndex gi(gf, std::max(1e-9, gl.h0));
      for (std::uint32_t k : qs) {
        std::vector<std::pair<float, std::uint32_t>> nn;
        gi.knn(qf[k], 1, nn);
        in_g.push_back(nn.empty() ? 0 : nn[0].second);
      }
    }
    // As scale.h: the noise over the first M / step of them, the scale test over all.
    const std::vector<std::size_t> in_g_sigma(
        in_g.begin(), in_g.begin() + static_cast<std::ptrdiff_t>(qf.size() / step));
    const TileScale ts =
        scale_from_neighbourhoods(gathered, in_g_sigma, in_g, gl.h0, frame.diag, use_v, o);
    if (ts.reach <= R || R >= frame.whole) {
      gl.h = ts.h;
      gl.noise_sigma = ts.noise_sigma;
      gl.noise_sigma_h0 = ts.noise_sigma_h0;
      gl.h_noise = ts.h_noise;
      return;
    }
    R = std::min(ts.reach * 1.25, frame.whole);
  }
}

}  // namespace

GlobalPasses global_passes(const TiledSource& src, const FilterOptions& o, double halo_factor,
                           std::array<std::uint64_t, 2> range, std::size_t chunk,
                           const TileComm& comm,
                           const std::function<void(const std::string&, double)>& progress) {
  GlobalPasses g;
  TiledGlobals& gl = g.globals;
  if (progress) progress("first pass", 0);
  const std::vector<Eigen::Vector3d> samples = first_pass(src, o, range, chunk, comm, g);
  if (gl.points == 0) return g;
  Frame frame;
  frame.origin = gl.box.center();
  frame.diag = gl.box.diagonal().norm();
  frame.fallback_h = frame.diag > 0 ? 1e-3 * frame.diag : 1e-3;
  frame.whole = 2 * frame.diag + frame.fallback_h;
  g.grid = occupancy_grid(gl.box);
  std::vector<Eigen::Vector3f> qf;  // the samples, float, relative to the origin
  for (const Eigen::Vector3d& p : samples) qf.push_back((p - frame.origin).cast<float>());
  std::vector<double> kth;
  histogram_and_neighbours(src, o, range, chunk, comm, frame, qf, kth, g);
  gl.h0 = 0;
  if (o.scale == ScaleMode::kFixed) {
    gl.h = o.h;
  } else {
    const double med = median_of(kth);
    gl.h0 = med > 0 ? med : frame.fallback_h;
    gl.h = gl.h0;
  }
  if (o.scale == ScaleMode::kAuto) noise_and_scale(src, o, range, chunk, comm, frame, qf, g);

  // What follows from h, as robust_filter decides it on the whole cloud.
  const int K = o.scale == ScaleMode::kAdaptive ? o.k_adaptive : o.k_h;
  gl.mean_spacing =
      (o.scale == ScaleMode::kAuto ? gl.h0 : gl.h) / std::sqrt(static_cast<double>(K) / M_PI);
  gl.merge_eps = o.merge_eps < 0 ? 0.25 * gl.mean_spacing : o.merge_eps;
  if (o.kernel_stride > 0)
    gl.kernel_stride = o.kernel_stride;
  else if (o.scale == ScaleMode::kAuto && gl.h0 > 0)
    gl.kernel_stride =
        static_cast<int>(std::clamp(std::floor((gl.h / gl.h0) * (gl.h / gl.h0)), 1.0, 64.0));
  else if (o.scale == ScaleMode::kAdaptive)
    gl.kernel_stride = std::clamp(o.k_adaptive / o.k_h, 1, 64);
  gl.min_component_size =
      o.min_component_size > 0
          ? o.min_component_size
          : std::max<std::size_t>(
                static_cast<std::size_t>(o.k_min),
                static_cast<std::size_t>(std::ceil(1e-3 * static_cast<double>(gl.points))));
  // kAdaptive: the halo from a high percentile of the sampled h_i (the largest support).
  double h_reach = gl.h;
  if (o.scale == ScaleMode::kAdaptive && !kth.empty()) {
    std::vector<double> s = kth;
    std::sort(s.begin(), s.end());
    h_reach = s[s.size() * 95 / 100];
  }
  gl.halo = halo_factor * h_reach;
  return g;
}

}  // namespace scanclean::detail
