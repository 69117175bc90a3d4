#include "projection.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "candidate_eval.h"
#include "cell_select.h"
#include "huge_pages.h"
#include "off_surface.h"
#include "parallel.h"

namespace scanclean::detail {
namespace {

struct ProjectionContext {
  std::uint64_t cell_key = 0;  // the kernel index's key in the thread-local cell caches
  const KernelSet* ks = nullptr;
  const FilterOptions* o = nullptr;
  float t2 = 9;  // truncation_sigma^2
  // A kernel j is gathered only within reach_scale sigma_j + kRegatherMargin h of where the
  // gather is (KernelRecord::kSigma): farther, it is truncated wherever the point can be before
  // it gathers again. The off-surface test may also read the kernels up to first_reach_scale
  // (outlier_sigma) sigma_j, gathered apart when it needs them.
  float reach_scale = 3, first_reach_scale = 3;
  float slab2 = 1;             // slab^2
  bool l_from_step = true;     // slab >= 1: the step keeps every kernel L keeps (StepSums)
  double gather_factor = 1;    // candidate_radius
  OffSurfaceTest off_surface;  // threshold2 = 0: off
};

// The fast path of the gather (cell_select.h): the same candidates, in the same order, as the
// loop over for_each_cell_run's runs below (the same cells, in the same order, and the same
// distance test).
bool gather_cell(const ProjectionContext& ctx, const Eigen::Vector3f& of, float r, float scale,
                 float margin, CandidateBuffer& buf) {
  CellSelect& sel = thread_cell_select();
  const KernelRecord* records = ctx.ks->records.data();
  const std::size_t n = sel.select_within_reach(
      *ctx.ks->index, ctx.cell_key, of, r, [&](std::uint32_t s) { return records[s].sigma(); },
      scale, margin);
  if (n == CellSelect::kNotGrid) return false;
  const float origin[3] = {of.x(), of.y(), of.z()};
  buf.clear();
  append_records(buf, ctx.ks->records.data(), sel.hits(), n, origin, ctx.slab2);
  buf.finish();
  return true;
}

// The candidate kernels of a point at `of`: every kernel whose centre lies within
// gather_factor h (candidate_radius) and within scale sigma_j + kRegatherMargin h, relative to
// `of`.
void gather(const ProjectionContext& ctx, const Eigen::Vector3f& of, double h, float scale,
            CandidateBuffer& buf) {
  const KernelSet& ks = *ctx.ks;
  const float r = static_cast<float>(ctx.gather_factor * h), r2 = r * r;
  const float margin = static_cast<float>(kRegatherMargin * h);
  if (gather_cell(ctx, of, r, scale, margin, buf)) return;
  const float origin[3] = {of.x(), of.y(), of.z()};
  buf.clear();
  const KernelRecord* records = ks.records.data();
  const bool grid = ks.index->for_each_cell_run(of, r, [&](std::uint32_t b, std::uint32_t e) {
    constexpr std::uint32_t kChunk = 64;
    std::uint32_t hit[kChunk];
    for (std::uint32_t s0 = b; s0 < e; s0 += kChunk) {
      const std::uint32_t s1 = std::min(e, s0 + kChunk);
      std::uint32_t n = 0;
      for (std::uint32_t s = s0; s < s1; ++s) {  // branch-free selection on compact centres
        const float* k = ks.index->slot_point(s).data();
        const float dx = k[0] - origin[0], dy = k[1] - origin[1], dz = k[2] - origin[2];
        const float d2 = dx * dx + dy * dy + dz * dz;
        const float reach = scale * records[s].sigma() + margin;  // as select_within_reach
        hit[n] = s;
        n += d2 < r2 && d2 < reach * reach ? 1u : 0u;
      }
      append_records(buf, records, hit, n, origin, ctx.slab2);
    }
  });
  if (!grid)
    ks.index->for_each_slot_within(of, r, [&](std::uint32_t s, float d2) {
      const float reach = scale * records[s].sigma() + margin;
      if (d2 < reach * reach) buf.push_record(s, records[s], origin, ctx.slab2);
    });
  buf.finish();
}

// The normal of the first candidate whose e_j (buffer.f[kE], from min_mahalanobis) is e_min.
Eigen::Vector3f best_kernel_normal(const CandidateBuffer& buf, float e_min) {
  using B = CandidateBuffer;
  const std::size_t best = first_candidate_with_e(buf, e_min);
  return {buf.f[B::kNx][best], buf.f[B::kNy][best], buf.f[B::kNz][best]};
}

struct PointOutcome {
  float L = 0;
  std::uint8_t iterations = 0;
  ProjectionState state = ProjectionState::kConverged;
  Eigen::Vector3f normal = Eigen::Vector3f::Zero();
};

// Projects x (in place) onto a maximum of L; eqs. 6-10 with the options' update rule.
PointOutcome project_point(const ProjectionContext& ctx, Eigen::Vector3d& x, double h,
                           Eigen::Vector3f nref) {
  using B = CandidateBuffer;
  thread_local B buf;
  const FilterOptions& o = *ctx.o;
  PointOutcome out;
  const double tol = o.tolerance * h, regather = kRegatherMargin * h;
  bool have_ref = nref.squaredNorm() > 0.5f;
  Eigen::Vector3f of = x.cast<float>();
  Eigen::Vector3d origin = of.cast<double>();
  gather(ctx, of, h, ctx.reach_scale, buf);
  // The first step reuses the e_j and d_j of the off-surface test, at the same position.
  bool first_step_ready = false;
  float first_e_min = std::numeric_limits<float>::infinity();  // the smallest of those e_j
  if (ctx.off_surface.threshold2 > 0 && buf.count > 0) {
    // Only points the kernels support at all (as the first iteration will check); the others
    // are left to be flagged unsupported. The kernels the steps read (within reach_scale
    // sigma_j) decide that: the others have e_j above truncation_sigma^2 here. Kernels up to
    // first_reach_scale sigma_j may also vouch for the point: they are gathered only when
    // those within reach_scale do not (few points; the steps then read the shorter list).
    const Eigen::Vector3d xl = x - origin;
    const float xf[3] = {static_cast<float>(xl.x()), static_cast<float>(xl.y()),
                         static_cast<float>(xl.z())};
    first_e_min = min_mahalanobis(buf, xf);
    if (first_e_min < ctx.t2 && !vouched(ctx.off_surface, buf, xl, nref)) {
      bool wide_vouched = false;
      if (ctx.first_reach_scale > ctx.reach_scale) {
        thread_local B wide;
        gather(ctx, of, h, ctx.first_reach_scale, wide);
        min_mahalanobis(wide, xf);
        wide_vouched = vouched(ctx.off_surface, wide, xl, nref);
      }
      if (!wide_vouched) {
        out.state = ProjectionState::kOffSurface;
        out.normal = nref;
        return out;
      }
    }
    first_step_ready = true;
  }
  // x relative to the candidates' origin, in float; the candidates are gathered again around x
  // once it has moved by more than kRegatherMargin h from where they were gathered.
  auto local_position = [&](float xf[3]) {
    if ((x - origin).norm() > regather) {
      of = x.cast<float>();
      origin = of.cast<double>();
      gather(ctx, of, h, ctx.reach_scale, buf);
      first_step_ready = false;
    }
    const Eigen::Vector3d xl = x - origin;
    for (int a = 0; a < 3; ++a) xf[a] = static_cast<float>(xl[a]);
  };
  int iters = 0;
  bool converged = false;
  Eigen::Vector3f nbar_out = nref;
  const Eigen::Vector3d start = x;
  double prev_mu = 0, prev_step = 0;  // of the last normal step
  double L = 0;                       // at the last iterate where the sums were formed
  for (int k = 0; k < o.max_iterations; ++k) {
    float xf[3];
    local_position(xf);
    if (!have_ref) {
      // No own kernel and no sensor normal: the reference is the normal of the kernel with the
      // smallest e_j here, chosen before the sums (their normal part depends on it). When no
      // e_j is below t2, no kernel is kept and the step below says so.
      if (!first_step_ready) {
        first_e_min = min_mahalanobis(buf, xf);
        first_step_ready = true;
      }
      if (first_e_min < ctx.t2) {
        nref = best_kernel_normal(buf, first_e_min);
        have_ref = true;
      }
    }
    StepSums s;
    const bool kept = first_step_ready
                          ? step_sums_after_min_mahalanobis(buf, nref.data(), ctx.t2, s)
                          : step_sums(buf, xf, nref.data(), ctx.t2, s);
    first_step_ready = false;
    if (!kept) {
      out.state = ProjectionState::kUnsupported;
      out.iterations = static_cast<std::uint8_t>(iters);
      out.normal = nref;
      x = start;
      return out;
    }
    L = s.likelihood();
    const Eigen::Vector3d m(s.dn[0] / s.s, s.dn[1] / s.s, s.dn[2] / s.s);
    Eigen::Vector3d nb(s.n[0], s.n[1], s.n[2]);
    const double nb_len = nb.norm();
    nb = nb_len > 1e-12 * s.s ? Eigen::Vector3d(nb / nb_len) : nref.cast<double>();
    const double mu = m.dot(nb);
    // Both updates stop on the normal part |mu| (eq. 10 on the normal part, docs/ALGORITHM.md
    // section 3): the tangential part of m never dies out.
    if (o.update == UpdateMode::kNormal) {
      // Secant step along the normal (normal_step): the stopping test still uses the measured
      // mu, so the fixed point and the tolerance are unchanged.
      const double step = normal_step(mu, prev_mu, prev_step);
      x -= step * nb;
      prev_mu = mu;
      prev_step = step;
    } else {
      x -= m;
    }
    const double step_len = std::abs(mu);
    ++iters;
    nbar_out = nb.cast<float>();
    if (step_len < tol) {
      converged = true;
      break;
    }
  }
  if (ctx.l_from_step) {
    // L where the last sums were formed: the last step of a converged point moved it by less
    // than kMaxSecantFactor x the tolerance, so evaluating L again there would cost a pass for
    // nothing.
    out.L = static_cast<float>(L);
  } else {
    float xf[3];
    local_position(xf);
    out.L = static_cast<float>(likelihood(buf, xf, ctx.t2));
  }
  out.iterations = static_cast<std::uint8_t>(std::min(iters, 255));
  out.state = converged ? ProjectionState::kConverged : ProjectionState::kNotConverged;
  out.normal = nbar_out;
  return out;
}

}  // namespace

double normal_step(double mu, double prev_mu, double prev_step) {
  const double dmu = prev_mu - mu;
  // dmu / prev_step estimates the slope c; it must be positive (a maximum ahead), and the
  // factor 1 / c is capped.
  if (prev_step == 0 || !(dmu * prev_step > 0)) return mu;
  return mu * std::min(prev_step / dmu, kMaxSecantFactor);
}

double candidate_radius(const FilterOptions& o) {
  return std::max(1.0, o.truncation_sigma / 3.0) + kRegatherMargin;
}

void project_all(const PointSet& d, const KernelSet& ks, const std::vector<Eigen::Vector3f>& nref,
                 const FilterOptions& o, bool off_surface_test, bool oriented,
                 const std::vector<std::uint8_t>& sparse, std::vector<Eigen::Vector3d>& x,
                 Projected& out, const std::string& phase) {
  ProjectionContext ctx;
  ctx.cell_key = new_cell_cache_key();
  ctx.ks = &ks;
  ctx.o = &o;
  ctx.t2 = static_cast<float>(o.truncation_sigma * o.truncation_sigma);
  // 1 % more: the kernels' S_j^-1 and sigma_j are rounded to float, and so are e_j and the
  // distances.
  ctx.reach_scale = static_cast<float>(1.01 * o.truncation_sigma);
  ctx.slab2 = static_cast<float>(o.slab * o.slab);
  ctx.l_from_step = o.slab >= 1;
  ctx.gather_factor = candidate_radius(o);
  ctx.off_surface.kernels = &ks;
  ctx.first_reach_scale = ctx.reach_scale;
  if (off_surface_test && !ks.fits.empty()) {
    ctx.off_surface.threshold2 = static_cast<float>(o.outlier_sigma * o.outlier_sigma);
    ctx.first_reach_scale =
        static_cast<float>(1.01 * std::max(o.truncation_sigma, o.outlier_sigma));
  }
  ctx.off_surface.floor2 = o.eigen_floor * o.eigen_floor;
  ctx.off_surface.oriented = oriented;
  const std::size_t n = x.size();
  assign_huge(out.L, n, 0.0f);
  assign_huge<std::uint8_t>(out.iterations, n, 0);
  assign_huge(out.state, n, ProjectionState::kConverged);
  assign_huge(out.normal, n, Eigen::Vector3f(Eigen::Vector3f::Zero()));
  parallel_each_reporting(n, o, phase, [&](std::size_t i) {
    // Sensor normals are the reference orientation when present, else the own kernel's normal.
    const Eigen::Vector3f ref = d.has_v(i) ? d.v[i] : nref[i];
    if (sparse[i]) {  // dropped before projection
      out.state[i] = ProjectionState::kSparse;
      out.normal[i] = ref;
      return;
    }
    const PointOutcome r = project_point(ctx, x[i], d.hi_at(i), ref);
    out.L[i] = r.L;
    out.iterations[i] = r.iterations;
    out.state[i] = r.state;
    out.normal[i] = r.normal;
  });
}

}  // namespace scanclean::detail
