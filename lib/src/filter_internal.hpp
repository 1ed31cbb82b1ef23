// beaconloc — private parts of the filter shared by its translation units:
// filter.cpp (init, start, predict, estimate), snapshot.cpp (the snapshot
// (re)start and its last-pulse table), aid_pulse.cpp (pulse arrival times),
// aid_wheels.cpp (wheel speeds), aid_bearing.cpp (bearings),
// snapshot_bearing.cpp (the triangulation (re)start). Every measurement goes through fuse_scalar
// (fusion.hpp).
#ifndef BEACONLOC_FILTER_INTERNAL_HPP
#define BEACONLOC_FILTER_INTERNAL_HPP

#include "fusion.hpp"

namespace bl {

constexpr uint32_t kFilterMagic = 0x424c4631u;  // "BLF1"
constexpr uint32_t kFlagStarted = 1u;
constexpr uint32_t kFlagConverged = 2u;
constexpr uint32_t kFlagEverStarted = 4u;

// State indices (filter.h BL_IX_*), short.
enum : int {
    X = BL_IX_X,
    Y = BL_IX_Y,
    TH = BL_IX_THETA,
    V = BL_IX_V,
    W = BL_IX_OMEGA,
    S = BL_IX_S,
    T = BL_IX_T,
    T0 = BL_IX_T0,
    KL = BL_IX_KL,
    KR = BL_IX_KR
};

inline Eigen::Map<VX> state(bl_filter *f) { return Eigen::Map<VX>(f->x_); }
inline Eigen::Map<const VX> state(const bl_filter *f) { return Eigen::Map<const VX>(f->x_); }
inline Eigen::Map<MX> cov(bl_filter *f) { return Eigen::Map<MX>(f->P_); }
inline Eigen::Map<const MX> cov(const bl_filter *f) { return Eigen::Map<const MX>(f->P_); }

inline bool initialised(const bl_filter *f) { return f != nullptr && f->magic_ == kFilterMagic; }
inline bool started(const bl_filter *f) { return initialised(f) && (f->flags_ & kFlagStarted); }

bool all_finite(const bl_real *v, int n);

// ---- filter.cpp
// t0 += k·T (the reference moves k firing slots), then whole microseconds
// move from the t0 offset into the epoch.
void shift_reference(const bl_config *cfg, VX &x, MX &P, int64_t &epoch_us, uint32_t &ref, int64_t k);
// Wheel scales at a (re)start: kept by a started filter, else 1 ± σ.
void start_wheel_scales(const bl_filter *f, VX &x, MX &P);
// Store x, P as the filter's state and update the converged flag.
void commit(bl_filter *f, const VX &x, const MX &P);

// ---- snapshot.cpp
// Keep a pulse in the last-pulse table (explained: it was fused).
void remember_pulse(bl_filter *f, uint32_t beacon_index, int64_t arrival_us, uint32_t receiver_index,
                    bool explained = false);
// The beacons whose latest firing the state could not explain, when they
// cover min_beacons; else ~0u (every beacon).
uint32_t restart_mask(const bl_filter *f, uint32_t min_beacons);
// (Re)start from the snapshot of the table's last cycle; *f untouched on failure.
int start_from_snapshot(bl_filter *f, real theta, real sigma_theta, real omega_radps, real s_mps, real var_s, real T_s,
                        real var_T, uint32_t min_beacons, uint32_t use_mask = ~0u);

// Where a measurement time lies against the state time t_s (bearings;
// aid_pulse.cpp classifies pulses the same way).
enum class MeasTime {
    kFresh,  // |t - t_s| <= max_predict_gap_s: fused
    kStale,  // t > t_s + max_predict_gap_s: no predict for that long (kept, restart)
    kTooOld  // t < t_s - max_predict_gap_s: time went backwards (BL_ETIME)
};
inline MeasTime classify_time(const bl_filter *f, int64_t t_us)
{
    int64_t d_us;
    if (!sub_us(t_us, f->t_us_, &d_us)) return t_us < f->t_us_ ? MeasTime::kTooOld : MeasTime::kStale;
    if (d_us > int64_t(1e12)) return MeasTime::kStale;
    if (d_us < -int64_t(1e12)) return MeasTime::kTooOld;
    const real d_s = us_to_s(d_us);
    if (d_s > f->cfg_.max_predict_gap_s) return MeasTime::kStale;
    if (-d_s > f->cfg_.max_predict_gap_s) return MeasTime::kTooOld;
    return MeasTime::kFresh;
}

#if BL_WITH_BEARINGS
// ---- snapshot_bearing.cpp
// Keep a bearing as its beacon's latest (the triangulation's input).
void remember_bearing(bl_filter *f, uint32_t bearing_beacon_index, int64_t t_us, real bearing_rad);
// (Re)start from the triangulation of the kept bearings (filter.h,
// bl_filter_start_bearings); *f untouched on failure.
int start_from_bearings(bl_filter *f);
#endif

#if BL_WITH_RANGES
// ---- snapshot_range.cpp
// Keep a time of flight as its range beacon's latest (the trilateration's input).
void remember_range(bl_filter *f, uint32_t range_beacon_index, int64_t t_us, real time_of_flight_s);
// (Re)start from the trilateration of the kept ranges (filter.h,
// bl_filter_start_ranges); *f untouched on failure.
int start_from_ranges(bl_filter *f);
#endif

// ---- aid_wheels.cpp
struct WheelSpeedCounts {
    uint32_t fused;    // scalar wheel-speed updates fused
    uint32_t refused;  // refused by fuse_scalar (non-finite result)
};
// Kleeman eq. 25: the wheel speeds over dt_s > 0 from the calibrated wheel
// distances left_m, right_m as measurements of v and ω.
void fuse_wheel_speeds(const bl_config *cfg, real left_m, real right_m, real dt_s, VX &x, MX &P,
                       WheelSpeedCounts *counts);

}  // namespace bl

#endif
