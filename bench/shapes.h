#pragma once
//! \file shapes.h
//! Ground-truth shapes of the protocol (docs/ALGORITHM.md, "Evaluation protocol"): each is
//! normalised to the unit sphere (bounding-box centre at the origin, largest radius 1), can be
//! sampled uniformly by area with a seeded generator and answers the exact unsigned distance of a
//! point to its surface. Units: the normalised unit (the bounding sphere has radius 1).

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <filesystem>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "rng.h"

namespace scanclean::bench {

class Shape {
 public:
  virtual ~Shape() = default;
  virtual std::string name() const = 0;
  //! n points distributed uniformly by surface area (deterministic for a given rng state).
  virtual std::vector<Eigen::Vector3d> sample(std::size_t n, Rng& rng) const = 0;
  //! Exact unsigned distance from p to the surface. Thread-safe.
  virtual double distance(const Eigen::Vector3d& p) const = 0;
  //! Axis-aligned bounding box of the surface.
  virtual Eigen::AlignedBox3d box() const = 0;
  //! Surface area.
  virtual double area() const = 0;
  //! Shapes with sharp creases: the distance from the point of the surface nearest to p to the
  //! nearest crease (the edge-band metric's test). Others: +infinity.
  virtual double crease_distance(const Eigen::Vector3d& /*p*/) const {
    return std::numeric_limits<double>::infinity();
  }
  virtual bool has_creases() const { return false; }
};

//! Unit sphere.
std::unique_ptr<Shape> make_sphere();
//! Torus around z with tube radius 0.3 and centre-line radius 0.7 (outer radius 1).
std::unique_ptr<Shape> make_torus();
//! Rounded box: the Minkowski sum of a box with half extents proportional to (0.5, 0.35, 0.2)
//! and a ball of radius proportional to 0.15, scaled so that its corners lie on the unit sphere.
std::unique_ptr<Shape> make_rounded_box();
//! The shapes at the filter's known limits (README, "Known limits"), exact distances:
//! thin_plate: a closed wedge plate, 1.7 x 1 (before normalisation), whose two large faces are
//! 0.01 apart at one end and 0.32 at the other (linearly in x): 0.1 h to 3 h at the protocol's h.
std::unique_ptr<Shape> make_thin_plate();
//! sharp_box: the rounded box's box, half extents proportional to (0.5, 0.35, 0.2), without
//! rounding (twelve 90-degree creases), corners on the unit sphere.
std::unique_ptr<Shape> make_sharp_box();
//! cad_block: a fandisk-like CAD part, a house-shaped prism (pentagonal section: walls, two roof
//! faces) with creases of 90, 117 and 127 degrees.
std::unique_ptr<Shape> make_cad_block();
//! two_scale: one sphere of radius 0.70 with fine detail around it, 0.11 away: two small tori
//! (tube radius 0.068) and four small spheres (radius 0.091), all disjoint; bounding radius 1.
std::unique_ptr<Shape> make_two_scale();
//! The four shapes above, in that order.
std::vector<std::unique_ptr<Shape>> limit_shapes();

//! The point of s's surface nearest to p, where it is unique: p moved against the (central
//! difference) gradient of the exact distance by that distance, repeated until the distance is
//! below 1e-9 of the unit (at most 8 steps). The benchmark's ideal projection.
Eigen::Vector3d closest_point(const Shape& s, const Eigen::Vector3d& p);

//! A triangle mesh read with io's read_triangle_mesh and normalised (vertices' bounding-box centre
//! to the origin, farthest vertex at radius 1); distances by eval::MeshDistance.
//! \throw UnavailableError if the benchmark was built without the io/eval modules;
//!        InputError/IoError from the reader.
std::unique_ptr<Shape> make_mesh_shape(const std::filesystem::path& ply, const std::string& name);

}  // namespace scanclean::bench
