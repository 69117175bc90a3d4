// CGAL Poisson surface reconstruction (implicit function + surface mesher).
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/IO/facets_in_complex_2_to_triangle_mesh.h>
#include <CGAL/Implicit_surface_3.h>
#include <CGAL/Poisson_reconstruction_function.h>
#include <CGAL/Random.h>
#include <CGAL/Surface_mesh.h>
#include <CGAL/Surface_mesh_default_triangulation_3.h>
#include <CGAL/make_surface_mesh.h>
#include <CGAL/property_map.h>

#include <algorithm>
#include <utility>

#include "cgal_reconstruction.h"

namespace scanclean::mesh_detail {

TriangleMesh poisson(const std::vector<Eigen::Vector3d>& points,
                     const std::vector<Eigen::Vector3f>& normals, double spacing, double angle,
                     double radius, double distance) {
  using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
  using Point = Kernel::Point_3;
  using Vector = Kernel::Vector_3;
  using Sphere = Kernel::Sphere_3;
  using PointWithNormal = std::pair<Point, Vector>;
  using Function = CGAL::Poisson_reconstruction_function<Kernel>;
  using Tr = CGAL::Surface_mesher::Surface_mesh_default_triangulation_3_generator<Kernel>::Type;
  using C2t3 = CGAL::Surface_mesh_complex_2_in_triangulation_3<Tr>;
  using Surface = CGAL::Implicit_surface_3<Kernel, Function>;

  // The surface mesher draws its initial points from CGAL's default random generator, which
  // is seeded from the clock: seed it so that the same input gives the same mesh.
  CGAL::get_default_random() = CGAL::Random(0);
  std::vector<PointWithNormal> pwn;
  pwn.reserve(points.size());
  for (std::size_t i = 0; i < points.size(); ++i)
    pwn.emplace_back(Point(points[i].x(), points[i].y(), points[i].z()),
                     Vector(normals[i].x(), normals[i].y(), normals[i].z()));
  Function function(pwn.begin(), pwn.end(), CGAL::First_of_pair_property_map<PointWithNormal>(),
                    CGAL::Second_of_pair_property_map<PointWithNormal>());
  TriangleMesh out;
  if (!function.compute_implicit_function()) return out;
  const Point inner = function.get_inner_point();
  const Sphere bsphere = function.bounding_sphere();
  const double r = std::sqrt(CGAL::to_double(bsphere.squared_radius()));
  const double sphere_radius = 5.0 * r;
  const double dichotomy_error = distance * spacing / 1000.0;
  Surface surface(function, Sphere(inner, sphere_radius * sphere_radius),
                  dichotomy_error / sphere_radius);
  CGAL::Surface_mesh_default_criteria_3<Tr> criteria(angle, radius * spacing, distance * spacing);
  Tr tr;
  C2t3 c2t3(tr);
  CGAL::make_surface_mesh(c2t3, surface, criteria, CGAL::Manifold_with_boundary_tag());
  if (tr.number_of_vertices() == 0) return out;
  CGAL::Surface_mesh<Point> sm;
  CGAL::facets_in_complex_2_to_triangle_mesh(c2t3, sm);
  out.vertices.reserve(sm.number_of_vertices());
  std::vector<int> index(sm.num_vertices(), -1);
  for (auto v : sm.vertices()) {
    const Point& p = sm.point(v);
    index[static_cast<std::size_t>(v)] = static_cast<int>(out.vertices.size());
    out.vertices.emplace_back(p.x(), p.y(), p.z());
  }
  out.triangles.reserve(sm.number_of_faces());
  for (auto f : sm.faces()) {
    std::array<int, 3> t{};
    int k = 0;
    for (auto v : CGAL::vertices_around_face(sm.halfedge(f), sm)) {
      if (k < 3) t[static_cast<std::size_t>(k)] = index[static_cast<std::size_t>(v)];
      ++k;
    }
    if (k == 3) out.triangles.push_back(t);
  }
  // CGAL lists the facets in an order that follows memory addresses: put them in a canonical
  // order (each rotated to start at its smallest index, orientation kept; then sorted).
  for (auto& t : out.triangles)
    std::rotate(t.begin(), std::min_element(t.begin(), t.end()), t.end());
  std::sort(out.triangles.begin(), out.triangles.end());
  return out;
}

}  // namespace scanclean::mesh_detail
