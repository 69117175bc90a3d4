#pragma once
//! \file surface_reconstruction.h
//! From clean points to a triangle mesh, with CGAL 5.5 (kept out of this header):
//!  - kAdvancingFront: CGAL's advancing-front surface reconstruction (Cohen-Steiner and Da, 2004).
//!    Interpolating: the mesh's vertices are the input points, in input order (points the front
//!    never reached stay as unreferenced vertices). Open surfaces stay open; no normals needed.
//!    Triangles with an edge longer than max_edge are never added, so gaps wider than that (the
//!    filter's h: the scale at which the surface was measured) are not bridged.
//!  - kPoisson: CGAL's Poisson surface reconstruction (Kazhdan, Bolitho and Hoppe, 2006) from the
//!    points and their oriented normals, meshed by CGAL's surface mesher (Boissonnat and Oudot).
//!    Approximating and watertight: new vertices on the implicit surface; holes in the data are
//!    closed.
//! Units: those of the cloud (metres).

#include <array>
#include <cstddef>
#include <functional>
#include <string>
#include <vector>

#include "scanclean/core/point_cloud.h"
#include "scanclean/core/triangle_mesh.h"
#include "scanclean/mesh/mesh_topology.h"

namespace scanclean {

enum class MeshMethod { kAdvancingFront, kPoisson };

//! "afront" / "poisson".
const char* to_string(MeshMethod method);
//! Parses "afront" or "poisson". \throw OptionError naming the value and the accepted ones.
MeshMethod parse_mesh_method(const std::string& name);

//! How the normals for Poisson are made consistent.
enum class NormalOrientation {
  kAuto,  //!< keep them if every k-NN pair agrees, else orient by MST
  kKeep,  //!< use the input normals as they are
  kMst,   //!< always re-orient by CGAL::mst_orient_normals (top point's normal points up, +z)
};

struct MeshOptions {
  MeshMethod method = MeshMethod::kAdvancingFront;
  //! Average point spacing (metres); 0 = CGAL::compute_average_spacing over spacing_k neighbours.
  double spacing = 0;
  int spacing_k = 6;  //!< neighbours of the automatic spacing, [1, 100]
  //! The filter's kernel size h (metres), when known (from the filtered file's provenance); 0 =
  //! unknown. Used for the automatic max_edge.
  double h = 0;
  //! kAdvancingFront: longest triangle edge admitted (metres); 0 = automatic: 2 h when h is
  //! known, else 10 x spacing. Negative = no limit.
  double max_edge = 0;
  double radius_ratio_bound = 5.0;  //!< kAdvancingFront: CGAL's K (boundaries), > 0
  double beta = 0.52;               //!< kAdvancingFront: CGAL's wedge half-angle (rad), (0, pi/2)
  //! kPoisson: mesher criteria, CGAL's defaults: minimum triangle angle (degrees, (0, 30]), the
  //! largest Delaunay-ball radius and the surface-approximation distance, both x spacing.
  double poisson_angle = 20.0;
  double poisson_radius = 30.0;
  double poisson_distance = 0.375;
  NormalOrientation orientation = NormalOrientation::kAuto;
  int orient_k = 18;  //!< neighbours of the orientation check and of the MST, [3, 200]
  //! Progress report (phase, fraction in [0, 1]); CGAL reports no progress inside a phase, so
  //! this is called at phase boundaries.
  std::function<void(const std::string& phase, double fraction)> progress;
};

//! Throws OptionError naming the option, the value and the valid range.
void validate(const MeshOptions& options);

//! The smallest cloud reconstruct_surface accepts.
constexpr std::size_t kMinMeshPoints = 10;

struct MeshResult {
  TriangleMesh mesh;
  MeshMethod method = MeshMethod::kAdvancingFront;
  MeshTopology topology;
  double spacing = 0;               //!< average spacing used (metres)
  double max_edge = 0;              //!< kAdvancingFront: edge limit used (metres; 0 = none)
  std::size_t normals_flipped = 0;  //!< kPoisson: input normals re-oriented
  bool normals_reoriented = false;  //!< kPoisson: the MST orientation ran
  double normal_agreement = 0;      //!< kPoisson: share of k-NN pairs whose normals agreed
  double seconds_spacing = 0, seconds_normals = 0, seconds_reconstruction = 0, seconds_total = 0;
};

//! Reconstructs a surface from `cloud`. kPoisson needs normals (any orientation with kMst; the
//! filter's are consistent when the input had sensor normals). \throw OptionError (validate),
//! InputError when the cloud has fewer than kMinMeshPoints points, non-finite coordinates, no
//! normals (kPoisson) or zero normals, or when the reconstruction produces no triangle (e.g. all
//! points collinear for kAdvancingFront). Triangles come in a canonical order (each piece
//! oriented to a positive signed volume: closed pieces face outwards). kPoisson is deterministic
//! (CGAL's random generator is seeded); kAdvancingFront is on clean samples, but CGAL breaks ties
//! between equal candidates by memory address, so on noisy input a few percent of the triangles
//! can differ between runs.
MeshResult reconstruct_surface(const PointCloud& cloud, const MeshOptions& options = {});

//! Average distance to the k nearest neighbours, averaged over the points
//! (CGAL::compute_average_spacing). \throw InputError for fewer than k + 1 points.
double average_spacing(const PointCloud& cloud, int k = 6);

//! Estimated oriented normals for a cloud without them (or to replace them): CGAL jet-fitted
//! normals over k neighbours, oriented by CGAL::mst_orient_normals over mst_k neighbours (0 = k;
//! the top point's normal points up). Points whose normal could not be oriented keep the jet
//! normal. \throw InputError for fewer than kMinMeshPoints points.
std::vector<Eigen::Vector3f> estimate_normals(const PointCloud& cloud, int k = 18, int mst_k = 0);

//! CGAL's oriented normals for a cloud without them, for the filter's
//! FilterOptions::normals_orient_only: CGAL's PCA normals over k neighbours, oriented by
//! CGAL::mst_orient_normals over max(6, k / 2). What `scanclean filter --orient-normals k` used
//! before the filter oriented normals itself (FilterOptions::orient_k, the same recipe); kept as
//! the benchmark's reference for it (`scanclean_bench --orient-normals-cgal`). The MST's graph
//! holds most of the memory (on the 290k merged bunny scans, k = 96: 1.3 GB peak).
//! \throw InputError for fewer than k + 1 points (or kMinMeshPoints).
std::vector<Eigen::Vector3f> estimate_orienting_normals(const PointCloud& cloud, int k);
//! The MST's neighbour count of estimate_orienting_normals for k: max(6, k / 2).
int orienting_mst_k(int k);

}  // namespace scanclean
