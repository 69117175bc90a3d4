// --tune: how the peers' neighbourhood sizes in peer_settings.cpp were chosen. Averages CD and
// P2M over the three analytic shapes on a tuning seed (not the protocol's seed) for a grid of k.
#include <cmath>
#include <iostream>

#include "peers.h"
#include "protocol.h"
#include "suites.h"

namespace scanclean::bench {

int tune_main(std::size_t n, std::uint64_t seed, double only_sigma,
              const std::filesystem::path& bunny) {
  std::vector<std::unique_ptr<Shape>> shapes;
  shapes.push_back(make_sphere());
  shapes.push_back(make_torus());
  shapes.push_back(make_rounded_box());
  try {
    shapes.push_back(make_mesh_shape(bunny, "bunny"));
  } catch (const std::exception& e) {
    std::cout << "bunny left out: " << e.what() << "\n";
  }
  const std::vector<unsigned> grid = n >= 30000 ? std::vector<unsigned>{48, 96, 192, 384, 576}
                                                : std::vector<unsigned>{12, 24, 48, 96, 192, 384};
  std::cout << "N=" << n << " tuning seed " << seed << "; mean over";
  for (const auto& sh : shapes) std::cout << " " << sh->name();
  std::cout << "\n";
  std::cout << "sigma  method     k    CD x1e4  P2M x1e4\n";
  for (double sigma : {0.01, 0.02, 0.03}) {
    if (only_sigma > 0 && std::abs(sigma - only_sigma) > 1e-9) continue;
    std::vector<Instance> insts;
    std::vector<std::unique_ptr<GroundTruth>> gts;
    for (std::size_t s = 0; s < shapes.size(); ++s) {
      InstanceSpec spec;
      spec.n = n;
      spec.sigma = sigma;
      spec.seed = derive_seed(seed, s, n, static_cast<std::uint64_t>(sigma * 1000));
      insts.push_back(make_instance(*shapes[s], spec));
      gts.push_back(std::make_unique<GroundTruth>(*shapes[s], insts.back().clean, 50000,
                                                  derive_seed(seed, 50 + s)));
    }
    for (const std::string method : {"jet", "bilateral", "pca"}) {
      for (unsigned k : grid) {
        if (method == "bilateral" && k > 192) continue;
        double cd = 0, p2m = 0;
        for (std::size_t s = 0; s < shapes.size(); ++s) {
          Points out;
          if (method == "jet") out = cgal_jet_smooth(insts[s].input, k);
          if (method == "bilateral") out = cgal_bilateral_smooth(insts[s].input, k, 25, 3);
          if (method == "pca") out = pca_plane_projection(insts[s].input, static_cast<int>(k));
          const Metrics m = evaluate(*gts[s], out);
          cd += m.cd / shapes.size();
          p2m += m.p2m / shapes.size();
        }
        std::printf("%.2f   %-9s %4u  %7.3f  %7.3f\n", sigma, method.c_str(), k, cd, p2m);
        std::fflush(stdout);
      }
    }
  }
  return 0;
}

}  // namespace scanclean::bench
