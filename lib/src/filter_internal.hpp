// beaconloc — private parts of the filter shared by its translation units:
// filter.cpp (init, start, predict), filter_sos.cpp (the speed of sound's
// model), filter_estimate.cpp (the estimate), snapshot.cpp (the snapshot
// (re)start and its last-pulse table), aid_pulse.cpp (pulse arrival times),
// aid_wheels.cpp (wheel speeds), and every measurement kind's sources
// (kinds.h: aid_<kind>.cpp, its start without a prior). Every measurement
// goes through fuse_scalar (fusion.hpp). A kind's own state is its
// aid_<kind>.h's (BL_<KIND>_FILTER), its hooks into the shared code kinds.hpp.
#ifndef BEACONLOC_FILTER_INTERNAL_HPP
#define BEACONLOC_FILTER_INTERNAL_HPP

#include <cstring>

#include "fusion.hpp"

namespace bl {

constexpr uint32_t kFilterMagic = 0x424c4631u;  // "BLF1"
constexpr uint32_t kFlagStarted = 1u;
constexpr uint32_t kFlagConverged = 2u;
constexpr uint32_t kFlagEverStarted = 4u;
// Not started, but the wheel scales and their 2x2 covariance in x_, P_ are
// a re-initialised filter's (reinit_keeping_wheel_scales): the next start
// takes them.
constexpr uint32_t kFlagScalesKept = 8u;
// Bits 8-13: 1 + the beacon a snapshot start's fault exclusion left out
// (snapshot.cpp solve_excluding: heard through an echo), 0 for none. Its
// pulses are not fused until the filter converges: while the start-up σ
// and gate are wide, that beacon's echo, the same every cycle, would pull
// the fix away again. Cleared at convergence (commit) and by every start.
constexpr uint32_t kExcludedShift = 8u;
constexpr uint32_t kExcludedMask = 63u << kExcludedShift;
static_assert(BL_MAX_BEACONS < 63, "flags_ bits 8-13 hold 1 + a beacon index");
inline bool startup_excluded(const bl_filter *f, uint32_t beacon_index)
{
    return ((f->flags_ & kExcludedMask) >> kExcludedShift) == beacon_index + 1u;
}
// Bit 14: the caller numbers the pulses with a sequencer that may be a whole
// number of slots off (the localizer): a snapshot start may renumber them
// from their geometry (snapshot.cpp renumber_fix). Kept by every start; set
// by the localizer at its init and every re-initialisation (which may
// change the site: a site without a sequencer leaves it clear).
// Bits 16-19: the shift a start applied (the table's beacon j is beacon
// (j + shift) mod N), for the localizer to apply to its sequencer and clear
// (take_renumbered); 0 for none.
constexpr uint32_t kFlagRenumber = 1u << 14;
// Bit 20: a site with range beacons is learning the heading from the track
// (aid_range.cpp): the robot moves with its heading unknown, the ranges go to
// the tried headings, and the filter is not converged. Cleared by every start.
constexpr uint32_t kFlagHeadingTrack = 1u << 20;
inline bool learning_heading(const bl_filter *f) { return BL_WITH_RANGES && (f->flags_ & kFlagHeadingTrack) != 0; }
constexpr uint32_t kRenumberedShift = 16u;
constexpr uint32_t kRenumberedMask = 15u << kRenumberedShift;
static_assert(BL_MAX_BEACONS <= 16, "flags_ bits 16-19 hold a shift < BL_MAX_BEACONS");
inline uint32_t take_renumbered(bl_filter *f)
{
    const uint32_t k = (f->flags_ & kRenumberedMask) >> kRenumberedShift;
    f->flags_ &= ~kRenumberedMask;
    return k;
}

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

// The odometry's effective wheel base (m): the ICR model of skid steering
// (Mandow et al. 2007; config.h wheels.skid_factor), χ·b; b for a
// differential drive (χ = 1).
inline real effective_base_m(const bl_config *cfg) { return cfg->wheels.skid_factor * cfg->wheel_base_m; }

// The midpoint odometry step of a dead reckoning (the bearings' motion
// compensation, aid_bearing.cpp; the ranges' heading from the track,
// aid_range.cpp) (Kleeman 1992 eq. 24; Vander et al. 2011 eq. 2):
// d = (d_l + d_r)/2, δ = (d_r - d_l)/b, x += d cos(θ + δ/2), y += d sin(θ + δ/2),
// θ += δ (pose: x, y in m, θ in rad; d_m in m, dth_rad in rad).
inline void odometry_step(real pose[3], real d_m, real dth_rad)
{
    const real mid = pose[2] + real(0.5) * dth_rad;
    pose[0] += d_m * std::cos(mid);
    pose[1] += d_m * std::sin(mid);
    pose[2] = wrap_angle(pose[2] + dth_rad);
}

// ---- filter.cpp (and filter_sos.cpp: the speed of sound's model)
// t0 += k·T (the reference moves k firing slots), then whole microseconds
// move from the t0 offset into the epoch.
// sos (optional): the air's modes' offsets of t0 moved alike (filter_sos.cpp).
void shift_reference(const bl_config *cfg, VX &x, MX &P, int64_t &epoch_us, uint32_t &ref, int64_t k,
                     bl_sos_drift *sos = nullptr);
// The beacons' firing times jumped by dt_s (s): the beacon controller
// restarted and fires on from a new time (localizer.cpp, timing_jump).
// Kleeman 1992 eq. 15's t0 moves by the jump, its variance grows by var_s2
// (s²); the pose, the speeds and every other state are kept. (The next
// predict moves the whole microseconds into the epoch: shift_reference.)
inline void shift_firing_times(bl_filter *f, real dt_s, real var_s2)
{
    f->x_[BL_IX_T0] += dt_s;
    f->P_[BL_IX_T0 * BL_FILTER_NX + BL_IX_T0] += var_s2;
}
// Wheel scales at a (re)start: kept by a started filter (or one
// re-initialised with them kept), else 1 ± σ.
void start_wheel_scales(const bl_filter *f, VX &x, MX &P);
// bl_filter_init with the same configuration, keeping what the filter has
// learned of the wheels (their scales and covariance) for its next start,
// when calibration is on; nothing else survives. The localizer's restart
// after a time gap (localizer.cpp reinit_filter).
void reinit_keeping_wheel_scales(bl_filter *f);
// The speed of sound's bank of air rates (filter_sos.cpp): the prediction
// of s over dt (s) with the bank (bl_sos_drift), updated, the filter's state
// moved by still air's share of the modes' switch; the bank at a start; an
// accepted pulse update into the bank (H at the prior, R in s², nu = z - h(x̄)
// in s; before the commit, f's covariance the prior's); and the bank's
// mixture on the published estimate's first kOut states (x, y, θ, v, ω, s).
using SosDrift = bl_sos_drift;
constexpr int kOut = S + 1;
void sos_drift_predict(const bl_config *cfg, SosDrift &sos, VX &x, MX &P, real dt);
void sos_drift_start(SosDrift &sos);
void sos_bank_update(bl_filter *f, const RX &H, real R, real nu);
void sos_bank_estimate(const SosDrift &sos, real *xm, real (*Pm)[kOut]);
// Its constants (ours, docs/performance.md "Speed of sound", "A bank of air
// rates"): the bank's largest rate r_d (m/s², 0.1 ≈ 10 °C per minute: s
// moves 0.6 m/s per °C) as a multiple of the still-air random walk σ_d, the
// modes at ±r_d/2 and ±r_d (a grid over the rate at half its spacing: the
// two rates alone followed a ramp at half their rate worse than no bank);
// the modes' switching time T_s (s: a rate is kept for about a quarter of
// an hour, a swing that turns back is a switch); still air's prior.
constexpr real kSosDriftRate_per_sqrt_s = real(2);
// r_d = kSosDriftRate_per_sqrt_s · speed_of_sound_drift_mps_per_sqrt_s
// (m/s²): one key sets how fast the air may change, 0.1 m/s² at the
// default 0.05 m/s/√s; a site that declares still air (e.g. 0.01) gets a
// bank too small to matter.
inline real sos_drift_rate_mps2(const bl_config *cfg)
{
    return kSosDriftRate_per_sqrt_s * cfg->speed_of_sound_drift_mps_per_sqrt_s;
}
constexpr real kSosRateTime_s = real(1000);
constexpr real kSosStillPrior = real(0.5);
static_assert(BL_SOS_OFFSET_STATES == BL_IX_T0 + 1 && kOut <= BL_SOS_OFFSET_STATES,
              "the bank's offsets are the states x .. t0");
// Store x, P as the filter's state and update the converged flag.
void commit(bl_filter *f, const VX &x, const MX &P);
// A (re)start's bookkeeping, shared by every start: epoch_us (us) and
// ref_beacon the reference firing, t_us (us) the state's time; the restart
// counted, the filter started and not converged, the team's cross-covariance
// forgotten, the air's modes' offsets but of s zeroed (filter.cpp).
void mark_started(bl_filter *f, int64_t epoch_us, uint32_t ref_beacon, int64_t t_us);
// The constant-velocity prediction over dt (s) with the parameters' noise
// and the speed of sound's model (filter.cpp; bl_filter_predict and the
// estimate's extrapolation, filter_estimate.cpp).
void cv_predict(const bl_config *cfg, SosDrift &sos, VX &x, MX &P, real dt);
// BL_OK if t_us is not before the state's time and within the predict gap,
// else BL_ETIME.
int check_time(const bl_filter *f, int64_t t_us);

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

// The ring's heading as a measurement (filter.h "Heading from the ring"):
// while the state's heading σ exceeds the ring's (after a restart that
// could not take it, e.g. the kidnap only half a cycle old), the ring
// heading of the explained firings at the state's (x, y) is fused into
// the filter's state (Vander et al. 2011 eq. 3; σ as at a start).
// latest_us: the newest arrival.
void aid_ring_heading(bl_filter *f, int64_t latest_us);

// A measurement of one state i itself for fuse_scalar: h(x) = x(i) (its
// unit), H = e_i (linear: one iteration); any finite update. The wheel
// speeds (v, ω) and the ring's heading (θ, with z on the branch nearest
// x(θ)) share it, and so one instance of the update.
template <int N> struct StateModel {
    int i;
    bool measure(const VN<N> &x, real *h, RN<N> *H) const
    {
        *h = x(i);
        *H = RN<N>::Zero();
        (*H)(i) = real(1);
        return true;
    }
    bool admissible(const VN<N> &, const VN<N> &) const { return true; }
    int unit_state() const { return i; }
};

// Where a measurement time lies against the state time t_s (every kind's
// measurement: pulses, bearings, ranges, sonar, thermometer, poses).
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

// A beacon source whose filter (re)starts from a snapshot of its own kind
// (bearings: the triangulation, snapshot_bearing.cpp; ranges: the
// trilateration, snapshot_range.cpp; `start`: its public start,
// bl_filter_start_<kind>s): what happens to one measurement z of
// beacon j at t_us before it can be fused. Before the start it is kept as
// its beacon's latest and a start from the kept ones is tried (status
// STARTED, else BUFFERED); one far older than a kept one (beyond
// max_predict_gap_s: keep the buffer on one timeline) is a caller error.
// Once started: older than the state by more than max_predict_gap_s is a
// caller error; newer by more than that (no predict for that long: the pose
// cannot be extrapolated so far) it is kept and a restart from the kept ones
// is tried (status RESET, else BUFFERED; the kept ones from before the gap
// are outside the window). Caller errors: BL_ETIME, *f untouched. Returns
// true when the measurement was taken care of here (*rc, and *res when
// *rc is BL_OK), false when it is fresh: fuse it.
inline bool snapshot_source_step(bl_filter *f, uint32_t count, uint32_t valid_mask, const int64_t *kept_t_us,
                                 void (*remember)(bl_filter *, uint32_t, int64_t, real), int (*start)(bl_filter *),
                                 uint32_t j, int64_t t_us, real z, bl_fusion_result *res, int *rc)
{
    *rc = BL_OK;
    if (!started(f)) {
        for (uint32_t k = 0; k < count; ++k)
            if ((valid_mask >> k) & 1u) {
                int64_t d_us;
                if (!sub_us(kept_t_us[k], t_us, &d_us) || us_to_s(d_us) > f->cfg_.max_predict_gap_s) {
                    *rc = BL_ETIME;
                    return true;
                }
            }
        remember(f, j, t_us, z);
        res->status = start(f) == BL_OK ? BL_FUSION_STARTED : BL_FUSION_BUFFERED;
        return true;
    }
    switch (classify_time(f, t_us)) {
    case MeasTime::kTooOld:
        *rc = BL_ETIME;
        return true;
    case MeasTime::kStale:
        remember(f, j, t_us, z);
        res->status = start(f) == BL_OK ? BL_FUSION_RESET : BL_FUSION_BUFFERED;
        return true;
    case MeasTime::kFresh:
        break;
    }
    return false;
}

#if BL_WITH_RANGES
// ---- snapshot_range.cpp: the automatic start from ranges, a first start
// confirmed by two rounds (a running filter's restart as
// bl_filter_start_ranges). BL_ENOCONVERGE while a round awaits the next.
int start_ranges_confirmed(bl_filter *f);
// ---- aid_range.cpp, shared with aid_team.cpp (the teammates' ranges)
// The range model (aid_range.h bl_filter_fuse_range) to a beacon at b: the
// time of flight h (s) to the receiver dt_s after the state time, H =
// ∂h/∂x (may be NULL), *d_m the range (may be NULL). False where undefined.
bool range_model_at(const bl_config *cfg, const bl_beacon &b, real dt_s, const VX &x, real *h, RX *H, real *d_m);
// The scalar measurement of a time of flight tof_s at the predicted range
// d_m (σ, gate by the convergence and heading σ; aid_range.h
// bl_filter_fuse_range) for a filter with covariance P.
ScalarMeasurement range_measurement(const bl_filter *f, const MX &P, real d_m, real tof_s);

#endif

// ---- aid_wheels.cpp
struct WheelSpeedCounts {
    uint32_t fused;    // scalar wheel-speed updates fused
    uint32_t refused;  // refused by fuse_scalar (non-finite result)
};
// Kleeman eq. 25: the wheel speeds over dt_s > 0 from the calibrated wheel
// distances left_m, right_m as measurements of v and ω, on the state (N =
// NX) or on the state augmented with consider states (N = NA, n_solve =
// NX: a team robot's, aid_team.cpp).
template <int N>
void fuse_wheel_speeds(const bl_config *cfg, real left_m, real right_m, real dt_s, VN<N> &x, MN<N> &P,
                       WheelSpeedCounts *counts, int n_solve = 0);

#if BL_WITH_TEAM
// ---- aid_team.cpp: the state augmented with the team beacons' (x, y), which the
// predicts (filter.cpp) and the wheel speeds (aid_wheels.cpp) carry: the one kind
// that changes the state's dimension
constexpr int NB = 2 * BL_TEAM_MAX_BEACONS;
constexpr int NA = NX + NB;
static_assert(NA == kTeamNA, "fusion.cpp instantiates the shared update's Joseph form at kTeamNA");
using VA = VN<NA>;
using MA = MN<NA>;
using CX = Mat<NX, NB>;  // cross-covariance state x beacons (m·unit of the state)
inline Eigen::Map<CX> team_cross(bl_filter *f) { return Eigen::Map<CX>(f->team_C_); }
inline Eigen::Map<const CX> team_cross(const bl_filter *f) { return Eigen::Map<const CX>(f->team_C_); }
// Beacons set in BL_TEAM_CONSIDER mode: predicts carry the cross-covariance.
inline bool team_consider(const bl_filter *f) { return f->team_count_ > 0 && f->team_mode_ == BL_TEAM_CONSIDER; }
// [x; b], [[P, C], [Cᵀ, P_bb]] (unused beacon slots: zero).
void team_join(const bl_filter *f, const VX &x, const MX &P, const CX &C, VA &xa, MA &Pa);
#endif
// A (re)start: the new pose is independent of the team beacons.
inline void team_forget_cross(bl_filter *f)
{
#if BL_WITH_TEAM
    std::memset(f->team_C_, 0, sizeof f->team_C_);
#else
    (void)f;
#endif
}
// Pulses, bearings and fixed-beacon ranges are refused while team beacons
// carry a cross-covariance (aid_team.h bl_filter_set_team_beacons).
inline bool team_blocks_other_sources(const bl_filter *f)
{
#if BL_WITH_TEAM
    return team_consider(f);
#else
    (void)f;
    return false;
#endif
}

}  // namespace bl

#endif
