// beaconloc — the pin-point corrector with memory (Hoppenot & Colle 1997
// §3.2, §5.2): the last ten bursts placed by odometry, segments by linear
// regression in Crowley's (1989) form, heading first, then position.
// Contract: sonar.h.
#include "sonar_internal.hpp"

#if BL_WITH_SONAR

#include <cstring>

using namespace bl;

namespace {

constexpr uint32_t kMemoryMagic = 0x424c4d31u;  // "BLM1"
// A fit whose impacts spread less than this along their principal axis
// (standard deviation, m) has no orientation (a robot standing still hits
// one spot ten times): not fitted (our choice).
constexpr real kMinSpread_m = real(0.03);
constexpr uint8_t kNoSegment = 0xff;
// A fit's impacts must lie within this many σ of a range of its line
// (rms across the fit).
constexpr real kAlignSigmas = real(2);

inline bool memory_ok(const bl_memory_corrector *m) { return m->magic_ == kMemoryMagic; }

// A fitted segment: Crowley's (1989) midpoint and orientation, and the known
// segment it was fitted to.
struct Fit {
    real cx, cy;   // midpoint (m): the impacts' centroid
    real phi;      // orientation (rad), modulo π
    real w;        // its weight in the heading step, 1/σφ² (1/rad²)
    uint32_t seg;  // index into the map
};

// The position step's problem (§3.2): the fitted midpoints, shifted by the
// pose's (x, y) from its value at the heading step, against their segments
// (association fixed: "the matching problem is solved").
struct Midpoints {
    const bl_map *map;
    const Fit *fits;
    uint32_t n;
    real x0, y0;  // pose position the midpoints were placed with (m)
};

LsEval midpoints_eval(const void *problem, const Vec3 &q)
{
    const Midpoints &p = *static_cast<const Midpoints *>(problem);
    LsEval e;
    e.F = 0;
    e.g.setZero();
    e.JtJ.setZero();
    e.matched = 0;
    for (uint32_t k = 0; k < p.n; ++k) {
        const Fit &f = p.fits[k];
        // eq. 3/4 for the midpoint moved with the robot; θ is not solved here.
        ls_add_term(p.map->segments[f.seg], f.cx + q(0) - p.x0, f.cy + q(1) - p.y0, 0, 0, &e);
    }
    return e;
}

// Orientation difference of two lines, modulo π, into (−π/2, π/2].
real line_angle_diff(real a, real b)
{
    real d = std::remainder(a - b, kPi);
    if (d <= real(-0.5) * kPi) d += kPi;
    return d;
}

}  // namespace

extern "C" int bl_memory_init(bl_memory_corrector *m, const bl_memory_params *params)
{
    if (m == nullptr) return BL_EINVAL;
    bl_memory_params def;
    if (params == nullptr) {
        bl_memory_default(&def);
        params = &def;
    }
    if (!memory_params_ok(params)) return BL_EINVAL;
    std::memset(m, 0, sizeof *m);
    m->params_ = *params;
    m->magic_ = kMemoryMagic;
    return BL_OK;
}

extern "C" int bl_memory_push(bl_memory_corrector *m, const bl_sonar_ring *ring, const bl_pose *pose_odometry,
                              const bl_sonar_range *burst, uint32_t n)
{
    if (m == nullptr || ring == nullptr || pose_odometry == nullptr || (n > 0 && burst == nullptr)) return BL_EINVAL;
    if (!memory_ok(m)) return BL_ENOTINIT;
    if (n > BL_SONAR_MAX_SENSORS || !pose_ok(pose_odometry)) return BL_EINVAL;
    if (bl_sonar_ring_check(ring, nullptr) != BL_OK) return BL_EINVAL;
    const uint32_t depth = m->params_.depth;
    const uint32_t slot = m->count_ == 0 ? 0 : (m->head_ + 1) % depth;
    uint32_t kept = 0;
    for (uint32_t k = 0; k < n; ++k) {
        const bl_sonar_range &r = burst[k];
        if (!sonar_range_usable(ring, r.sensor, r.range_m, r.flags, &m->dropped_)) continue;
        m->sensor_[slot][kept] = uint8_t(r.sensor);
        m->range_m_[slot][kept] = r.range_m;
        kept += 1;
    }
    m->n_[slot] = kept;
    m->odo_[slot] = *pose_odometry;
    m->head_ = slot;
    if (m->count_ < depth) m->count_ += 1;
    return BL_OK;
}

extern "C" int bl_memory_correct(const bl_memory_corrector *m, const bl_map *map, const bl_sonar_ring *ring,
                                 bl_pose *pose_in_out, bl_memory_result *result)
{
    if (m == nullptr || map == nullptr || ring == nullptr || pose_in_out == nullptr) return BL_EINVAL;
    if (!memory_ok(m)) return BL_ENOTINIT;
    if (!pose_ok(pose_in_out)) return BL_EINVAL;
    if (bl_map_check(map, nullptr) != BL_OK || bl_sonar_ring_check(ring, nullptr) != BL_OK) return BL_EINVAL;
    const bl_memory_params &prm = m->params_;
    bl_memory_result res;
    std::memset(&res, 0, sizeof res);
    res.dropped = m->dropped_;
    res.outcome = BL_PINPOINT_NONE;

    // Each kept burst's pose in the current estimate's frame, by odometry:
    // P_k = pose ∘ (odo_newest⁻¹ ∘ odo_k).
    const bl_pose &on = m->odo_[m->head_];
    const real x = pose_in_out->x_m, y = pose_in_out->y_m, th = pose_in_out->theta_rad;
    bl_pose bp[BL_MEMORY_MAX_BURSTS];
    const real cn = std::cos(on.theta_rad), sn = std::sin(on.theta_rad);
    const real c = std::cos(th), s = std::sin(th);
    for (uint32_t k = 0; k < m->count_; ++k) {
        const bl_pose &ok = m->odo_[k];
        const real dx = ok.x_m - on.x_m, dy = ok.y_m - on.y_m;
        const real rx = cn * dx + sn * dy, ry = -sn * dx + cn * dy;  // R(−θ_n)(p_k − p_n)
        bp[k].x_m = x + c * rx - s * ry;
        bp[k].y_m = y + s * rx + c * ry;
        bp[k].theta_rad = th + (ok.theta_rad - on.theta_rad);
    }
    // Matching (§3.2 "a sensor measure is assigned to a segment of the
    // environment taking odometric position into account"; §5.2 "a measure
    // is associated to a segment if and only if the difference between the
    // direction of the shot and the normal to the wall is less than 20
    // degrees"): the segment whose perpendicular foot lies within the
    // incidence gate of the shot and whose range explains the measured one
    // within the gate (eq. 2-4), the impact placed on that normal, where the
    // specular echo comes from (sonar_internal.hpp Echo; on the beam axis it
    // would be up to d(1 − cos 20°) = 6 % of the range short of the wall).
    uint8_t seg_of[BL_MEMORY_MAX_BURSTS][BL_SONAR_MAX_SENSORS];
    real imp_x[BL_MEMORY_MAX_BURSTS][BL_SONAR_MAX_SENSORS];  // impacts relative to the robot (m)
    real imp_y[BL_MEMORY_MAX_BURSTS][BL_SONAR_MAX_SENSORS];
    uint32_t per_seg[BL_MAP_MAX_SEGMENTS];
    std::memset(per_seg, 0, sizeof per_seg);
    for (uint32_t k = 0; k < m->count_; ++k)
        for (uint32_t i = 0; i < m->n_[k]; ++i) {
            seg_of[k][i] = kNoSegment;
            const uint32_t sensor = m->sensor_[k][i];
            if (sensor >= ring->count) continue;  // a ring smaller than the one pushed with
            res.points += 1;
            const bl_sonar_mount &mt = ring->mounts[sensor];
            real sx, sy, dsx, dsy;
            sonar_transducer(mt, bp[k].x_m, bp[k].y_m, bp[k].theta_rad, &sx, &sy, &dsx, &dsy);
            const real d = m->range_m_[k][i];
            Echo ec;
            const int j = nearest_echo(map, sx, sy, bp[k].theta_rad + mt.angle_rad, prm.incidence_gate_rad, d,
                                       ring->gate_m, true, &ec);
            if (j < 0) continue;
            // M = S + d (Q − S)/h, centred on the robot: the regression's
            // sums keep their precision far from the site origin.
            imp_x[k][i] = sx + d * (ec.qx - sx) / ec.h_m - x;
            imp_y[k][i] = sy + d * (ec.qy - sy) / ec.h_m - y;
            seg_of[k][i] = uint8_t(j);
            per_seg[j] += 1;
            res.matched += 1;
        }
    // Segments by linear regression in Crowley's form (midpoint,
    // orientation): the orthogonal regression of the impacts of each segment
    // with enough of them, φ = ½ atan2(2 Sxy, Sxx − Syy) (the principal
    // axis of their scatter).
    Fit fits[BL_MEMORY_MAX_FITS];
    uint32_t nf = 0;
    for (uint32_t j = 0; j < map->count && nf < BL_MEMORY_MAX_FITS; ++j) {
        if (per_seg[j] < prm.min_points) continue;
        real sx = 0, sy = 0, sxx = 0, sxy = 0, syy = 0, w = 0, sr = 0;
        for (uint32_t k = 0; k < m->count_; ++k)
            for (uint32_t i = 0; i < m->n_[k]; ++i) {
                if (seg_of[k][i] != j) continue;
                const real mx = imp_x[k][i], my = imp_y[k][i];
                w += 1;
                sr += m->range_m_[k][i];
                sx += mx;
                sy += my;
                sxx += mx * mx;
                sxy += mx * my;
                syy += my * my;
            }
        const real mx = sx / w, my = sy / w;
        const real cxx = sxx / w - mx * mx, cxy = sxy / w - mx * my, cyy = syy / w - my * my;
        // Largest eigenvalue of the scatter: the variance along the fit.
        const real half_tr = real(0.5) * (cxx + cyy);
        const real disc = std::sqrt(real(0.25) * (cxx - cyy) * (cxx - cyy) + cxy * cxy);
        const real along = half_tr + disc, across = half_tr - disc;  // variances (m²)
        if (!(along >= kMinSpread_m * kMinSpread_m)) continue;
        // Crowley's (1989) alignment test, here as a fit's quality (our
        // choice): the impacts must lie on a line within kAlignSigmas σ of a
        // range (a phantom or an unknown obstacle matched with a wall
        // scatters), and the orientation's standard error
        // σφ = σ_r / √(n·var_along) (the orthogonal regression's) must be at
        // most max_fit_sigma_rad: a short fit's orientation is its noise.
        real sigma_r = ring->sigma_range_rel * sr / w;
        if (sigma_r < ring->sigma_range_m) sigma_r = ring->sigma_range_m;
        if (!(across <= kAlignSigmas * kAlignSigmas * sigma_r * sigma_r)) continue;
        if (!(sigma_r * sigma_r <= prm.max_fit_sigma_rad * prm.max_fit_sigma_rad * w * along)) continue;
        fits[nf].cx = mx + x;
        fits[nf].cy = my + y;
        fits[nf].phi = real(0.5) * std::atan2(real(2) * cxy, cxx - cyy);
        fits[nf].seg = j;
        fits[nf].w = w * along / (sigma_r * sigma_r);  // 1/σφ², σφ² = σ_r²/(n·var_along)
        nf += 1;
    }
    res.segments = nf;
    if (nf < prm.min_segments) {
        if (result) *result = res;
        return BL_OK;
    }
    // Heading first (§3.2): the mean of (known − fitted) orientations.
    real dth = 0, wsum = 0;
    for (uint32_t k = 0; k < nf; ++k) {
        const bl_segment &sg = map->segments[fits[k].seg];
        dth += fits[k].w * line_angle_diff(std::atan2(sg.y2_m - sg.y1_m, sg.x2_m - sg.x1_m), fits[k].phi);
        wsum += fits[k].w;
    }
    dth /= wsum;
    // The fitted midpoints turn with the heading about the robot.
    const real cd = std::cos(dth), sd = std::sin(dth);
    for (uint32_t k = 0; k < nf; ++k) {
        const real rx = fits[k].cx - x, ry = fits[k].cy - y;
        fits[k].cx = x + cd * rx - sd * ry;
        fits[k].cy = y + sd * rx + cd * ry;
    }
    // Then position: the midpoints against their known segments, by the
    // same least squares (eq. 3/4, stopping rules, per-axis fall-back).
    const Midpoints mp = {map, fits, nf, x, y};
    const Vec3 q0(x, y, th + dth);
    const LsOutcome o = least_squares(midpoints_eval, &mp, prm.position, BL_AXIS_X | BL_AXIS_Y, q0, false);
    res.iterations = o.iterations;
    const real ddx = o.q(0) - x, ddy = o.q(1) - y;
    if (std::sqrt(ddx * ddx + ddy * ddy) > prm.position.max_correction_m ||
        std::fabs(dth) > prm.position.max_correction_rad) {
        res.outcome = BL_PINPOINT_REFUSED;
        if (result) *result = res;
        return BL_OK;
    }
    // The heading correction stands on its own (step one); the position
    // step's outcome decides x and y.
    res.outcome = o.outcome == BL_PINPOINT_NONE ? BL_PINPOINT_PARTIAL : o.outcome;
    res.axes = o.axes | BL_AXIS_THETA;
    res.dx_m = o.q(0) - x;
    res.dy_m = o.q(1) - y;
    res.dtheta_rad = dth;
    pose_in_out->x_m = o.q(0);
    pose_in_out->y_m = o.q(1);
    pose_in_out->theta_rad = wrap_angle(th + dth);
    if (result) *result = res;
    return BL_OK;
}

#endif  // BL_WITH_SONAR
