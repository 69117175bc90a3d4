#include "scanclean/pipeline/noise_model.h"

#include <algorithm>
#include <cmath>

namespace scanclean {

double nguyen_axial_sigma_m(double z_m, double theta_rad) {
  const double kMaxTheta = 89.9 * M_PI / 180.0;
  const double z = std::max(z_m, 1e-6);
  const double theta = std::clamp(theta_rad, 0.0, kMaxTheta);
  const double t = theta / (M_PI / 2.0 - theta);
  return 0.0012 + 0.0019 * (z - 0.4) * (z - 0.4) + (0.0001 / std::sqrt(z)) * t * t;
}

double ps1080_quantisation_step_m(double z_m, const std::optional<Ps1080Params>& params) {
  double zpd_mm = 120.0, zpps_mm = 0.1042, lddis_cm = 7.5, coeff = 4.0;
  if (params && params->zpd_mm > 0 && params->zpps_mm > 0 && params->lddis_cm > 0 &&
      params->param_coeff > 0) {
    zpd_mm = params->zpd_mm;
    zpps_mm = params->zpps_mm;
    lddis_cm = params->lddis_cm;
    coeff = params->param_coeff;
  }
  // dz[mm] = z[mm]^2 ZPPS[mm] / (ZPD[mm] LDDIS[mm] coeff); in metres: z[m]^2 * 100 ZPPS /
  // (ZPD LDDIS[cm] coeff).
  return z_m * z_m * 100.0 * zpps_mm / (zpd_mm * lddis_cm * coeff);
}

double depth_sigma_m(double z_m, double theta_rad, const std::optional<Ps1080Params>& params) {
  const double sz = nguyen_axial_sigma_m(z_m, theta_rad);
  const double dq = ps1080_quantisation_step_m(z_m, params);
  return std::sqrt(sz * sz + dq * dq / 12.0);
}

double nguyen_weight(double z_m, double theta_rad, const std::optional<Ps1080Params>& params) {
  const double ref = depth_sigma_m(0.8, 0.0, params);
  const double s = depth_sigma_m(z_m, theta_rad, params);
  const double r = ref / s;
  return std::clamp(r * r, 0.0, 1.0);
}

}  // namespace scanclean
