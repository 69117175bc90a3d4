// --self-test: checks of the harness itself against oracles (sampling, noise, metrics, outlier
// injection and classification, the PCA and SOR baselines). Exit code 0 only if all pass.
#include <cmath>
#include <iostream>

#include "peers.h"
#include "protocol.h"
#include "suites.h"

namespace scanclean::bench {

namespace {

struct Checker {
  int failed = 0, passed = 0;
  void check(bool ok, const std::string& what, double value) {
    std::cout << (ok ? "PASS " : "FAIL ") << what << " (value " << value << ")\n";
    (ok ? passed : failed)++;
  }
};

}  // namespace

int self_test_main(std::uint64_t seed) {
  Checker c;
  // 1. Samples lie on the surface; area uniformity on sphere caps and torus halves.
  {
    auto sphere = make_sphere();
    auto torus = make_torus();
    auto rbox = make_rounded_box();
    Rng rng(derive_seed(seed, 1));
    for (const Shape* s : {sphere.get(), torus.get(), rbox.get()}) {
      const auto pts = s->sample(20000, rng);
      double worst = 0, far = 0;
      for (const auto& p : pts) {
        worst = std::max(worst, s->distance(p));
        far = std::max(far, p.norm());
      }
      c.check(worst < 1e-9, s->name() + ": samples on the surface, max distance", worst);
      c.check(std::abs(far - 1.0) < 0.02 && far <= 1.0 + 1e-9,
              s->name() + ": farthest sample at radius ~1 (normalised)", far);
    }
    const auto sp = sphere->sample(200000, rng);
    double cap = 0;
    for (const auto& p : sp) cap += p.z() > 0.5 ? 1 : 0;
    cap /= sp.size();
    c.check(std::abs(cap - 0.25) < 0.005, "sphere: share of samples with z > 0.5 is 1/4", cap);
    const auto tp = torus->sample(200000, rng);
    double outer = 0;
    for (const auto& p : tp) outer += std::hypot(p.x(), p.y()) > 0.7 ? 1 : 0;
    outer /= tp.size();
    const double expect = 0.5 + 0.3 / (M_PI * 0.7);
    c.check(std::abs(outer - expect) < 0.005,
            "torus: share on the outer half is 1/2 + r/(pi R) = 0.636", outer);
  }
  // 1b. The shapes at the known limits: samples on the surface, normalised, exact distances at
  // known points (the box's centre: its smallest half extent; a corner: on a crease).
  {
    Rng rng(derive_seed(seed, 11));
    for (const auto& s : limit_shapes()) {
      const auto pts = s->sample(20000, rng);
      double worst = 0, far = 0;
      for (const auto& p : pts) {
        worst = std::max(worst, s->distance(p));
        far = std::max(far, p.norm());
      }
      c.check(worst < 1e-9, s->name() + ": samples on the surface, max distance", worst);
      c.check(far <= 1.0 + 1e-9 && far > 0.9, s->name() + ": samples within the unit sphere", far);
    }
    auto box = make_sharp_box();
    const double half_z = box->box().max().z();  // the smallest half extent
    c.check(std::abs(box->distance(Eigen::Vector3d::Zero()) - half_z) < 1e-12,
            "sharp_box: distance of the centre is the smallest half extent",
            box->distance({0, 0, 0}));
    const Eigen::Vector3d corner = box->box().max();
    c.check(box->crease_distance(corner) < 1e-12 && box->crease_distance({0, 0, half_z}) > 0.1,
            "sharp_box: a corner lies on a crease, a face centre does not",
            box->crease_distance({0, 0, half_z}));
    // closest_point: on the sphere the radial projection; on the box a point above a face drops
    // straight onto it, and a point outside an edge (beyond two faces) lands on the edge.
    {
      auto sphere = make_sphere();
      Rng prng(derive_seed(seed, 12));
      double worst = 0;
      for (int k = 0; k < 1000; ++k) {
        const Eigen::Vector3d p(0.2 * prng.normal() + 0.6, 0.2 * prng.normal(), prng.normal());
        worst = std::max(worst, (closest_point(*sphere, p) - p.normalized()).norm());
      }
      c.check(worst < 1e-7, "closest_point on the sphere is p / |p|, max error", worst);
      const Eigen::Vector3d top(0.05, -0.03, half_z + 0.02);
      const double face_err =
          (closest_point(*box, top) - Eigen::Vector3d(0.05, -0.03, half_z)).norm();
      c.check(face_err < 1e-7, "closest_point above a face of sharp_box drops onto it", face_err);
      const Eigen::Vector3d m = box->box().max();
      const Eigen::Vector3d beyond(0.1, m.y() + 0.01, m.z() + 0.02);
      const double edge_err =
          (closest_point(*box, beyond) - Eigen::Vector3d(0.1, m.y(), m.z())).norm();
      c.check(edge_err < 1e-6, "closest_point beyond an edge of sharp_box lands on the edge",
              edge_err);
    }
    auto two = make_two_scale();
    const double big = two->distance(Eigen::Vector3d::Zero());  // the big sphere's radius
    c.check(std::abs(big - 0.62 / 0.88) < 1e-12, "two_scale: big sphere radius 0.62 / 0.88", big);
  }
  // 2. Metrics against oracles.
  {
    auto sphere = make_sphere();
    InstanceSpec spec;
    spec.n = 50000;
    spec.sigma = 0.01;
    spec.seed = derive_seed(seed, 2);
    const Instance inst = make_instance(*sphere, spec);
    const GroundTruth gt(*sphere, inst.clean, 100000, derive_seed(seed, 3));
    const Metrics clean = evaluate(gt, inst.clean);
    c.check(clean.cd == 0.0, "CD of the clean sample against itself is 0", clean.cd);
    c.check(clean.coverage >= 0.99 && clean.coverage < 0.995,
            "coverage of the clean sample is 99 % by the tolerance's definition", clean.coverage);
    c.check(clean.mean_dist < 1e-12, "clean sample: mean distance to the surface 0",
            clean.mean_dist);
    const Metrics noisy = evaluate(gt, inst.input);
    c.check(std::abs(noisy.rms_dist - 0.01) < 0.0003, "noise sigma 0.01 gives RMS distance 0.01",
            noisy.rms_dist);
    c.check(std::abs(1e4 * noisy.rms_dist * noisy.rms_dist - 1.0) < 0.06,
            "P2M's output->surface term is sigma^2 x 1e4 = 1",
            1e4 * noisy.rms_dist * noisy.rms_dist);
    // Clean sample: P2M is only the dense -> sample term, for a uniform (Poisson) sample of
    // density lambda = N / A the mean squared nearest distance is 1 / (pi lambda).
    const double poisson = 1e4 * sphere->area() / (M_PI * 50000.0);
    c.check(std::abs(clean.p2m / poisson - 1) < 0.03, "P2M of the clean sample = A / (pi N) x 1e4",
            clean.p2m);
    // Half-normal statistics of |N(0, sigma)|: mean sigma sqrt(2/pi), p95 1.96 sigma.
    c.check(std::abs(noisy.mean_dist - 0.01 * std::sqrt(2 / M_PI)) < 0.0003,
            "mean distance = sigma sqrt(2/pi)", noisy.mean_dist);
    c.check(std::abs(noisy.p95_dist - 0.0196) < 0.0005, "p95 distance = 1.96 sigma",
            noisy.p95_dist);
    std::vector<Eigen::Vector3d> shifted = inst.clean;
    for (auto& p : shifted) p.x() += 0.001;
    const Metrics sh = evaluate(gt, shifted);
    // (A few pairs closer than 0.001 swap their nearest neighbour, which can only lower CD.)
    c.check(sh.cd <= 0.02 + 1e-12 && sh.cd > 0.0198,
            "CD of the clean sample shifted by 0.001 is 2 x 0.001^2 x 1e4", sh.cd);
    // Exact resampling (the quality suite's second reference row): an independent clean sample
    // of the same size. Each direction's mean squared nearest distance is then a Poisson
    // process's, 1 / (pi lambda), so CD = 2 A / (pi N) x 1e4.
    Rng fresh(derive_seed(seed, 13));
    const Metrics rs = evaluate(gt, sphere->sample(spec.n, fresh));
    c.check(std::abs(rs.cd / (2 * poisson) - 1) < 0.03,
            "CD of an independent clean sample of the same size = 2 A / (pi N) x 1e4", rs.cd);
  }
  // 3. Outlier injection and classification.
  {
    auto torus = make_torus();
    InstanceSpec spec;
    spec.n = 10000;
    spec.sigma = 0.01;
    spec.outliers = OutlierKind::kUniform;
    spec.outlier_fraction = 0.05;
    spec.seed = derive_seed(seed, 4);
    const Instance inst = make_instance(*torus, spec);
    std::size_t labelled = 0;
    double closest = 1e9;
    for (std::size_t i = 0; i < inst.input.size(); ++i) {
      if (!inst.is_outlier[i]) continue;
      ++labelled;
      closest = std::min(closest, torus->distance(inst.input[i]));
    }
    c.check(labelled == 500 && inst.outlier_count == 500, "5 % of 10k uniform outliers labelled",
            static_cast<double>(labelled));
    c.check(closest >= inst.outlier_min_distance, "outliers keep their minimum distance", closest);
    const GroundTruth gt(*torus, inst.clean, 20000, derive_seed(seed, 5));
    std::vector<std::uint8_t> kept(inst.input.size());
    std::vector<Eigen::Vector3d> out;
    for (std::size_t i = 0; i < kept.size(); ++i) {
      kept[i] = inst.is_outlier[i] ? 0 : 1;
      if (kept[i]) out.push_back(inst.input[i]);
    }
    const Metrics m = evaluate(gt, out, {&inst, &kept});
    c.check(m.precision == 1 && m.recall == 1 && m.retention == 1 && m.removed == 500,
            "perfect removal scores precision = recall = retention = 1", m.recall);
    kept[0] = 1 - kept[0];  // one wrong decision
    const Metrics m2 = evaluate(gt, out, {&inst, &kept});
    c.check(m2.recall < 1 || m2.retention < 1, "one wrong decision is seen", m2.retention);
    InstanceSpec clumps = spec;
    clumps.outliers = OutlierKind::kClumps;
    clumps.outlier_fraction = 0.01;
    const Instance ci = make_instance(*torus, clumps);
    c.check(ci.outlier_count >= 100 && ci.outlier_count < 150,
            "clumps reach 1 % of N (within one clump)", static_cast<double>(ci.outlier_count));
  }
  // 4. Baselines.
  {
    Rng rng(derive_seed(seed, 6));
    std::vector<Eigen::Vector3d> plane(5000);
    for (auto& p : plane) p = Eigen::Vector3d(rng.uniform(-1, 1), rng.uniform(-1, 1), 0.25);
    const auto same = pca_plane_projection(plane, 24);
    double worst = 0;
    for (std::size_t i = 0; i < plane.size(); ++i)
      worst = std::max(worst, (same[i] - plane[i]).norm());
    c.check(worst < 1e-12, "PCA projection keeps points of a plane", worst);
    std::vector<Eigen::Vector3d> noisy = plane;
    for (auto& p : noisy) p.z() += 0.01 * rng.normal();
    const auto proj = pca_plane_projection(noisy, 48);
    double rms_in = 0, rms_out = 0;
    for (std::size_t i = 0; i < plane.size(); ++i) {
      rms_in += std::pow(noisy[i].z() - 0.25, 2);
      rms_out += std::pow(proj[i].z() - 0.25, 2);
    }
    c.check(rms_out < 0.3 * rms_in, "PCA projection reduces plane noise (ratio of squares)",
            rms_out / rms_in);
    std::vector<Eigen::Vector3d> with_far = noisy;
    for (int i = 0; i < 5; ++i) with_far.emplace_back(rng.uniform(-1, 1), rng.uniform(-1, 1), 2.0);
    const auto keep = statistical_outlier_removal(with_far, 20, 2.0);
    int far_kept = 0;
    for (std::size_t i = noisy.size(); i < with_far.size(); ++i) far_kept += keep[i];
    c.check(far_kept == 0, "SOR removes 5 far points", far_kept);
    const auto keep_cgal =
        cgal_remove_outliers(with_far, 24, 100.0, 2 * cgal_average_spacing(with_far, 24));
    far_kept = 0;
    for (std::size_t i = noisy.size(); i < with_far.size(); ++i) far_kept += keep_cgal[i];
    c.check(far_kept == 0, "CGAL remove_outliers (through our wrapper) removes 5 far points",
            far_kept);
    const auto jet = cgal_jet_smooth(noisy, 48);
    double rms_jet = 0;
    for (const auto& p : jet) rms_jet += std::pow(p.z() - 0.25, 2);
    c.check(jet.size() == noisy.size() && rms_jet < 0.3 * rms_in,
            "CGAL jet (through our wrapper) keeps the count and reduces plane noise",
            rms_jet / rms_in);
  }
  std::cout << c.passed << " passed, " << c.failed << " failed\n";
  return c.failed == 0 ? 0 : 1;
}

}  // namespace scanclean::bench
