#pragma once
//! \file noise_model.h
//! Depth noise of PrimeSense-class (structured-light, PS1080) sensors, docs/SENSORS.md §4, and the
//! per-point confidence weights derived from it. Units: metres and radians.

#include <optional>

#include "scanclean/core/range_frame.h"

namespace scanclean {

//! Axial noise of Nguyen, Izadi, Lovell (2012): sigma_z = 0.0012 + 0.0019 (z - 0.4)^2 +
//! (0.0001 / sqrt(z)) theta^2 / (pi/2 - theta)^2, z in metres (> 0), theta the angle between
//! the viewing ray and the surface normal in [0, pi/2) (clamped to 89.9 degrees). Metres.
double nguyen_axial_sigma_m(double z_m, double theta_rad);

//! PS1080 depth quantisation step at depth z (1/8 pixel of disparity):
//! dz = z^2 ZPPS / (ZPD LDDIS ParamCoeff), with ZPPS and ZPD in mm and LDDIS in cm converted to
//! consistent units. Uses `params` when every constant is positive, else the typical constants
//! (ZPD 120 mm, ZPPS 0.1042 mm, LDDIS 7.5 cm, ParamCoeff 4), about 2.9e-3 z^2. Metres.
double ps1080_quantisation_step_m(double z_m, const std::optional<Ps1080Params>& params);

//! Total per-point depth standard deviation: sqrt(sigma_z(z, theta)^2 + dz(z)^2 / 12). Metres.
double depth_sigma_m(double z_m, double theta_rad, const std::optional<Ps1080Params>& params);

//! Confidence weight w = clamp((sigma_ref / sigma(z, theta))^2, 0, 1) with sigma_ref =
//! depth_sigma_m(0.8 m, 0). Falls with z and with theta; 1 up to about 0.8 m at normal incidence.
double nguyen_weight(double z_m, double theta_rad, const std::optional<Ps1080Params>& params);

}  // namespace scanclean
