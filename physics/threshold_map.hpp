#pragma once
// Fig. 3C / Fig. S21: the air speed at which forced convection dominates mixed convection,
// over a grid of air temperature and humidity, for a water-saturated skin.

namespace manikind::physics {

enum class FreeConvectionLaw { dt_only, eq8 };  // Eq. S8 (temperature only) or Eq. 8 (coupled)

struct ThresholdGrid {
    double air_temp_min_c = 20.0, air_temp_max_c = 50.0, air_temp_step_c = 1.0;
    double rh_min_pct = 10.0, rh_max_pct = 90.0, rh_step_pct = 10.0;
    double skin_temp_c = 35.0;
    double mix_to_forced_ratio = 1.05;
    FreeConvectionLaw law = FreeConvectionLaw::eq8;
};

struct ThresholdPoint {
    double air_temp_c = 0.0;
    double air_rh_pct = 0.0;
    double speed_m_s = 0.0;
    double h_free_w_m2k = 0.0;
};

// Threshold speed at one condition (dC from a saturated skin at skin_temp_c).
ThresholdPoint threshold_point(double air_temp_c, double air_rh_pct, double skin_temp_c,
                               double mix_to_forced_ratio, FreeConvectionLaw law);

// The grid point with the lowest threshold speed; grid points with C_air >= C_skin
// (condensation, excluded in the paper) are skipped.
ThresholdPoint minimum_threshold_on_grid(const ThresholdGrid& grid);

}  // namespace manikind::physics
