// beaconloc — snapshot bearing triangulation (aid_bearing.h): the pose (x, y,
// theta) from bearings to N >= 3 beacons, no prior.
//
// Measurement model, Vander et al. 2011 eq. 1 (eq. 3 in the filter):
//   phi_j = atan2(yb_j - ys, xb_j - xs) - theta,
// (xs, ys) = (x, y) + R(theta)·o the sensor, o its mount offset (body frame).
// Internally the unknowns are the sensor position and theta (q = (xs, ys,
// theta)): the model is then the paper's exactly, and the robot follows as
// (x, y) = s - R(theta)·o. The reparametrisation is one-to-one, so the
// least-squares fix and its first-order covariance are the same; both are
// mapped back to the robot with T = ∂(x, y, theta)/∂(xs, ys, theta).
//
// Three beacons: closed form (ToTal, Pierlot & Van Droogenbroeck, "A New
// Three Object Triangulation Algorithm for Mobile Robot Positioning", IEEE
// T-RO 30(3), 2014, Algorithm 1). Each pair's bearing difference fixes a
// circle through the two beacons and the sensor (inscribed angle theorem,
// Vander §2 Fig. 2); the sensor is where the circles meet, which is unique
// unless the sensor lies on the circle through the three beacons (Fig. 4,
// ToTal's D = 0).
// N beacons: weighted Gauss-Newton on the wrapped bearing residuals from
// the closed form of the best-conditioned triple.
// Displaced sensors (aid_bearing.h: body_dx_m, body_dy_m, body_dtheta_rad, a
// moving robot's bearings motion-compensated by odometry): bearing j's
// sensor sits at s_j = s + R(theta)·e_j, e_j = d_j + R(dθ_j)·o - o (body
// frame, from the reference pose's sensor s), and its bearing counts from
// theta + dθ_j. The unknowns stay q = (xs, ys, theta) of the reference
// pose; e_j = 0 and dθ_j = 0 give the one-sensor model exactly (every term
// they add is skipped, so the results are bit for bit the same).
#include "internal.hpp"

#include <cstring>
#include <limits>

#include "beaconloc/aid_bearing.h"

using bl::is_finite;
using bl::real;
using bl::Vec3;
using bl::wrap_angle;

namespace {

using Mat3 = bl::Mat<3, 3>;

constexpr uint32_t kMaxIterations = 20;
constexpr real kDefaultMaxDrms_m = real(0.5);
// A fix whose sensor-position drms exceeds kLinearity times the distance
// to the nearest beacon is refused: the error then reaches across the
// curvature of the bearings (atan2 is far from its tangent over the error
// ellipse) and the first-order covariance no longer describes the error.
// Near the degenerate circle this is what catches a fix that slid along
// the circle (measured: tests/lib/test_solver_bearing.c, the grid across
// the circle).
constexpr real kLinearity = real(0.5);
// Largest displacement of a sensor (m, rad; aid_bearing.h).
constexpr real kMaxDisplacement = real(1e3);
// An exactly determined fix (N = 3) must reproduce its bearings to within
// kConsistency·sigma_j (rounding only); else it is refused.
#if defined(BL_USE_FLOAT) && BL_USE_FLOAT
constexpr real kMinCondition = real(1e-4);
constexpr real kStepTol = real(1e-5);     // Gauss-Newton step (m and rad), or
constexpr real kStepRel = real(1e-3);     // this fraction of its σ (float rounding)
constexpr real kCotMax = real(1e5);       // clamp of an infinite cot (cot_diff)
constexpr real kCoincident = real(1e-5);  // relative beacon separation
constexpr real kConsistency = real(1e-2);
#else
constexpr real kMinCondition = real(1e-6);
constexpr real kStepTol = real(1e-9);
constexpr real kStepRel = real(0);
constexpr real kCotMax = real(1e8);
constexpr real kCoincident = real(1e-9);
constexpr real kConsistency = real(1e-4);
#endif

bool problem_valid(const bl_bearing_problem *p)
{
    if (p->count < 3 || p->count > BL_MAX_BEACONS) return false;
    if (!is_finite(p->sensor_x_m) || !is_finite(p->sensor_y_m)) return false;
    if (!is_finite(p->max_drms_m) || p->max_drms_m < real(0)) return false;
    for (uint32_t j = 0; j < p->count; ++j) {
        if (!is_finite(p->beacons[j].x_m) || !is_finite(p->beacons[j].y_m)) return false;
        if (!is_finite(p->bearing_rad[j])) return false;
        if (!is_finite(p->sigma_rad[j]) || !(p->sigma_rad[j] > real(0))) return false;
        const real d[3] = {p->body_dx_m[j], p->body_dy_m[j], p->body_dtheta_rad[j]};
        for (int k = 0; k < 3; ++k)
            if (!(std::fabs(d[k]) <= kMaxDisplacement)) return false;  // NaN fails too
    }
    return true;
}

bool displaced(const bl_bearing_problem *p)
{
    for (uint32_t j = 0; j < p->count; ++j)
        if (p->body_dx_m[j] != real(0) || p->body_dy_m[j] != real(0) || p->body_dtheta_rad[j] != real(0)) return true;
    return false;
}

// Bearing j in the reference body frame: phi_j + dθ_j (rad).
inline real turned_bearing(const bl_bearing_problem *p, uint32_t j)
{
    return p->body_dtheta_rad[j] != real(0) ? p->bearing_rad[j] + p->body_dtheta_rad[j] : p->bearing_rad[j];
}

// The sensors' offsets from the reference pose's sensor, body frame (m):
// e_j = d_j + R(dθ_j)·o - o (aid_bearing.h's model with s = (x, y) + R(theta)·o).
struct Offsets {
    real ex[BL_MAX_BEACONS];
    real ey[BL_MAX_BEACONS];
};

void sensor_offsets(const bl_bearing_problem *p, Offsets &o)
{
    const real ox = p->sensor_x_m, oy = p->sensor_y_m;
    for (uint32_t j = 0; j < p->count; ++j) {
        const real a = p->body_dtheta_rad[j];
        const real c = std::cos(a), s = std::sin(a);
        o.ex[j] = a != real(0) ? p->body_dx_m[j] + (c * ox - s * oy) - ox : p->body_dx_m[j];
        o.ey[j] = a != real(0) ? p->body_dy_m[j] + (s * ox + c * oy) - oy : p->body_dy_m[j];
    }
}

// The bearings as unit vectors (cos phi_j, sin phi_j): every angle
// difference below comes from products of these (no wrap needed, no trig).
struct Bearings {
    real c[BL_MAX_BEACONS];
    real s[BL_MAX_BEACONS];
};

void bearing_vectors(const bl_bearing_problem *p, Bearings &b)
{
    for (uint32_t j = 0; j < p->count; ++j) {
        const real a = turned_bearing(p, j);  // the reference body frame (= phi_j undisplaced)
        b.c[j] = std::cos(a);
        b.s[j] = std::sin(a);
    }
}

// cot(a_j - a_i) from the unit vectors of a_i, a_j, its magnitude clamped
// to kCotMax where the sine vanishes (sensor on the line through the two
// beacons): ToTal replaces the infinite cot by a large finite value; the
// fix then moves by O(1/kCotMax) of the beacon spacing.
inline real cot_diff(const Bearings &b, uint32_t i, uint32_t j)
{
    // sin(a_j - a_i) = s_j c_i - c_j s_i, cos(a_j - a_i) = c_j c_i + s_j s_i
    const real s = b.s[j] * b.c[i] - b.c[j] * b.s[i];
    const real c = b.c[j] * b.c[i] + b.s[j] * b.s[i];
    const real floor = real(1) / kCotMax;
    return c / (s < real(0) ? (s < -floor ? s : -floor) : (s > floor ? s : floor));
}

// Any two of beacons i, j, k closer than kCoincident times their extent.
bool coincident(const bl_bearing_problem *p, uint32_t i, uint32_t j, uint32_t k)
{
    const uint32_t id[3] = {i, j, k};
    real d2[3], dmax2 = 0;
    for (int a = 0; a < 3; ++a) {
        const bl_beacon &u = p->beacons[id[a]], &v = p->beacons[id[(a + 1) % 3]];
        const real dx = u.x_m - v.x_m, dy = u.y_m - v.y_m;
        d2[a] = dx * dx + dy * dy;
        if (d2[a] > dmax2) dmax2 = d2[a];
    }
    const real tol2 = kCoincident * kCoincident * dmax2;
    return !(dmax2 > real(0)) || d2[0] <= tol2 || d2[1] <= tol2 || d2[2] <= tol2;
}

// ToTal (Pierlot & Van Droogenbroeck 2014, Algorithm 1), beacons i, j, k in
// the roles B1, B2, B3 (B2 the origin of the modified coordinates). Sensor
// position (m); false when D = 0 or anything is not finite.
bool total(const bl_bearing_problem *p, const Bearings &b, uint32_t i, uint32_t j, uint32_t k, real &xs, real &ys)
{
    const real x2 = p->beacons[j].x_m, y2 = p->beacons[j].y_m;
    // Step 1, modified beacon coordinates: x'1 = x1 - x2, y'1 = y1 - y2,
    // x'3 = x3 - x2, y'3 = y3 - y2.
    const real x1 = p->beacons[i].x_m - x2, y1 = p->beacons[i].y_m - y2;
    const real x3 = p->beacons[k].x_m - x2, y3 = p->beacons[k].y_m - y2;
    // Step 2, the three cot: T12 = cot(a2 - a1), T23 = cot(a3 - a2),
    // T31 = cot(a1 - a3) (the paper's (1 - T12 T23)/(T12 + T23), the same
    // value; here its sine and cosine cost four products, no division by
    // T12 + T23 = 0 when the sensor is on the line through B1 and B3).
    const real T12 = cot_diff(b, i, j);
    const real T23 = cot_diff(b, j, k);
    const real T31 = cot_diff(b, k, i);
    // Step 3, modified circle centres (B2 at the origin; each circle passes
    // through the sensor and its two beacons, Vander Fig. 2):
    //   x'12 = x'1 + T12 y'1, y'12 = y'1 - T12 x'1,
    //   x'23 = x'3 - T23 y'3, y'23 = y'3 + T23 x'3,
    //   x'31 = (x'3 + x'1) + T31 (y'3 - y'1), y'31 = (y'3 + y'1) - T31 (x'3 - x'1).
    const real x12 = x1 + T12 * y1, y12 = y1 - T12 * x1;
    const real x23 = x3 - T23 * y3, y23 = y3 + T23 * x3;
    const real x31 = (x3 + x1) + T31 * (y3 - y1), y31 = (y3 + y1) - T31 * (x3 - x1);
    // Step 4: k'31 = x'1 x'3 + y'1 y'3 + T31 (x'1 y'3 - x'3 y'1).
    const real k31 = x1 * x3 + y1 * y3 + T31 * (x1 * y3 - x3 * y1);
    // Step 5: D = (x'12 - x'23)(y'23 - y'31) - (y'12 - y'23)(x'23 - x'31);
    // D = 0 exactly when the sensor is on the circle through B1, B2, B3
    // (Vander Fig. 4).
    const real D = (x12 - x23) * (y23 - y31) - (y12 - y23) * (x23 - x31);
    if (!(D != real(0)) || !is_finite(D)) return false;
    // Step 6: xR = x2 + k'31 (y'12 - y'23) / D, yR = y2 + k'31 (x'23 - x'12) / D.
    const real f = k31 / D;
    xs = x2 + f * (y12 - y23);
    ys = y2 + f * (x23 - x12);
    return is_finite(xs) && is_finite(ys);
}

// Heading from the sensor position on beacons id[0..2]: theta_j =
// angle(b_j - s) - phi_j for each beacon, combined as the circular mean
// weighted by 1/sigma_j² (exactly determined: all theta_j agree). Returns
// the mean's unit vector (cos theta, sin theta) and the largest
// |sin(theta_j - theta)| / sigma_j: the bearing residuals of the fix in σ
// (exactly determined, so rounding only for a true fix); false if undefined
// (sensor on a beacon).
bool heading(const bl_bearing_problem *p, const Bearings &b, const uint32_t id[3], real xs, real ys, real &cth,
             real &sth, real &spread)
{
    real vc[3], vs[3];
    real sc = 0, ss = 0;
    for (int a = 0; a < 3; ++a) {
        const uint32_t j = id[a];
        const real dx = p->beacons[j].x_m - xs, dy = p->beacons[j].y_m - ys;
        const real r = std::sqrt(dx * dx + dy * dy);
        if (!(r > real(0))) return false;
        const real w = real(1) / (p->sigma_rad[j] * p->sigma_rad[j]);
        // (cos, sin)(angle(u) - phi) = (ux c + uy s, uy c - ux s), u = (dx, dy)/r.
        vc[a] = (dx * b.c[j] + dy * b.s[j]) / r;
        vs[a] = (dy * b.c[j] - dx * b.s[j]) / r;
        sc += w * vc[a];
        ss += w * vs[a];
    }
    const real len = std::sqrt(sc * sc + ss * ss);
    if (!(len > real(0)) || !is_finite(len)) return false;
    cth = sc / len;
    sth = ss / len;
    spread = 0;
    for (int a = 0; a < 3; ++a) {
        // sin(theta_j - theta) = vs_j cos(theta) - vc_j sin(theta); a theta_j
        // opposite the mean (cos < 0) is inconsistent too: ToTal's cot fixes
        // the bearing differences only modulo π, so a noisy triple can give
        // the point that matches them with one beacon seen backwards.
        if (!(vc[a] * cth + vs[a] * sth > real(0))) {
            spread = std::numeric_limits<real>::infinity();
            break;
        }
        const real e = std::fabs(vs[a] * cth - vc[a] * sth) / p->sigma_rad[id[a]];
        if (!(e <= spread)) spread = e;
    }
    return is_finite(spread);
}

// Weighted normal matrix A = JᵀWJ at the sensor position (unknowns xs, ys,
// theta): the row of bearing j (Vander eq. 1 differentiated),
//   ∂phi_j/∂(xs, ys, theta) = (dy/r², -dx/r², -1), (dx, dy) = b_j - s_j,
// with a displaced sensor s_j = s + R(theta)·e_j (see the top) the theta
// entry gains ∂β/∂s_j · R'(theta)·e_j, R'(theta)·e = (-sin ex - cos ey,
// cos ex - sin ey); W = diag(1/sigma_j²). With res = true also g = JᵀW e
// and chi2 = Σ w e², e_j = wrap(phi_j + dθ_j - atan2(dy, dx) + theta)
// (rad). False if a sensor is on a beacon.
bool normal_equations(const bl_bearing_problem *p, const Offsets &off, const uint32_t *id, uint32_t n, const Vec3 &q,
                      bool res, Mat3 &A, Vec3 &g, real &chi2)
{
    A.setZero();
    g.setZero();
    chi2 = 0;
    const real cq = std::cos(q(2)), sq = std::sin(q(2));
    for (uint32_t a = 0; a < n; ++a) {
        const uint32_t j = id[a];
        const real ex = off.ex[j], ey = off.ey[j];
        const bool moved = ex != real(0) || ey != real(0);
        real dx = p->beacons[j].x_m - q(0), dy = p->beacons[j].y_m - q(1);
        if (moved) {
            dx -= cq * ex - sq * ey;  // s_j = s + R(theta)·e_j
            dy -= sq * ex + cq * ey;
        }
        const real r2 = dx * dx + dy * dy;
        if (!(r2 > real(0))) return false;
        const real w = real(1) / (p->sigma_rad[j] * p->sigma_rad[j]);
        Vec3 row;
        row << dy / r2, -dx / r2, real(-1);
        if (moved) row(2) += row(0) * (-sq * ex - cq * ey) + row(1) * (cq * ex - sq * ey);
        A.noalias() += (w * row) * row.transpose();
        if (res) {
            const real e = wrap_angle(turned_bearing(p, j) - std::atan2(dy, dx) + q(2));
            g.noalias() += (w * e) * row;
            chi2 += w * e * e;
        }
    }
    return true;
}

// Inverse of the symmetric positive definite A after Jacobi scaling
// (Â = S A S, S = diag(1/sqrt(A_kk)): unit diagonal, so the closed-form
// cofactor inverse loses no digits to the mixed units); false if singular.
bool scaled_inverse(const Mat3 &A, Mat3 &inv)
{
    Vec3 sc;
    for (int k = 0; k < 3; ++k) {
        if (!(A(k, k) > real(0))) return false;
        sc(k) = real(1) / std::sqrt(A(k, k));
    }
    const Mat3 As = sc.asDiagonal() * A * sc.asDiagonal();
    const real det = As.determinant();
    if (!(det > real(0)) || !is_finite(det)) return false;
    inv = sc.asDiagonal() * As.inverse() * sc.asDiagonal();
    return inv.allFinite();
}

// Reciprocal 1-norm condition number of the Jacobi-scaled Â = S A S,
// 1 / (‖Â‖₁ ‖Â⁻¹‖₁), from A and its inverse (Â⁻¹ = S⁻¹ A⁻¹ S⁻¹); in (0, 1].
real condition_of(const Mat3 &A, const Mat3 &inv)
{
    Vec3 d;  // sqrt of the diagonal: S = diag(1/d)
    for (int k = 0; k < 3; ++k) d(k) = std::sqrt(A(k, k));
    real n1 = 0, n1i = 0;
    for (int c = 0; c < 3; ++c) {
        real col = 0, coli = 0;
        for (int r = 0; r < 3; ++r) {
            col += std::fabs(A(r, c)) / (d(r) * d(c));
            coli += std::fabs(inv(r, c)) * (d(r) * d(c));
        }
        if (col > n1) n1 = col;
        if (coli > n1i) n1i = coli;
    }
    return real(1) / (n1 * n1i);
}

// The solution at the sensor fix q = (xs, ys, theta) (theta any wrap;
// cth, sth its cosine and sine, from the caller), A = JᵀWJ there, chi2 its
// weighted squared residuals over n bearings. Writes *out only if the fix passes
// every check (aid_bearing.h); returns BL_OK or BL_EDEGENERATE.
int finish(const bl_bearing_problem *p, const Vec3 &q, real cth, real sth, const Mat3 &A, real chi2, uint32_t n,
           uint32_t iterations, bl_bearing_solution *out)
{
    Mat3 cov_s;
    if (!scaled_inverse(A, cov_s)) return BL_EDEGENERATE;
    // Robot from sensor: (x, y) = s - R(theta)·o, so with (a, b) = ∂(x, y)/∂theta
    // = -R'(theta)·o = (sin·ox + cos·oy, -cos·ox + sin·oy):
    //   T = [[1, 0, a], [0, 1, b], [0, 0, 1]], cov = T cov_s Tᵀ,
    //   and the robot's normal matrix T⁻ᵀ A T⁻¹ (T⁻¹: a, b negated).
    const real ox = p->sensor_x_m, oy = p->sensor_y_m;
    const real a = sth * ox + cth * oy, b = -cth * ox + sth * oy;
    Mat3 T = Mat3::Identity(), Ti = Mat3::Identity();
    T(0, 2) = a;
    T(1, 2) = b;
    Ti(0, 2) = -a;
    Ti(1, 2) = -b;
    Mat3 cov = T.lazyProduct(cov_s).lazyProduct(T.transpose());
    const Mat3 Ar = Ti.transpose().lazyProduct(A).lazyProduct(Ti);
    for (int r = 0; r < 3; ++r)
        for (int c = r + 1; c < 3; ++c) cov(r, c) = cov(c, r) = real(0.5) * (cov(r, c) + cov(c, r));
    if (!cov.allFinite() || !Ar.allFinite() || !(Ar(0, 0) > 0) || !(Ar(1, 1) > 0) || !(Ar(2, 2) > 0))
        return BL_EDEGENERATE;
    const real condition = condition_of(Ar, cov);
    if (!(condition >= kMinCondition)) return BL_EDEGENERATE;
    // Exactly determined (n = 3): the fix must reproduce the bearings,
    // Σ e_j²/σ_j² <= 3 kConsistency² (see closed_form).
    if (n == 3 && !(chi2 <= real(3) * kConsistency * kConsistency)) return BL_EDEGENERATE;
    const real drms_m = std::sqrt(cov(0, 0) + cov(1, 1));
    const real max_drms_m = p->max_drms_m > real(0) ? p->max_drms_m : kDefaultMaxDrms_m;
    if (!(drms_m <= max_drms_m)) return BL_EDEGENERATE;
    real rmin2 = -1;  // squared distance sensor - nearest beacon (m²)
    for (uint32_t j = 0; j < p->count; ++j) {
        const real dx = p->beacons[j].x_m - q(0), dy = p->beacons[j].y_m - q(1);
        const real r2 = dx * dx + dy * dy;
        if (rmin2 < real(0) || r2 < rmin2) rmin2 = r2;
    }
    const real drms_s = std::sqrt(cov_s(0, 0) + cov_s(1, 1));
    if (!(drms_s <= kLinearity * std::sqrt(rmin2))) return BL_EDEGENERATE;
    // Weighted rms of the residuals with the 3 unknowns' degrees of freedom
    // removed (aid_bearing.h): sqrt(Σ w e² / Σ w · n / (n - 3)), 0 for n = 3.
    real residual_rad = 0;
    if (n > 3) {
        real wsum = 0;
        for (uint32_t j = 0; j < p->count; ++j) wsum += real(1) / (p->sigma_rad[j] * p->sigma_rad[j]);
        residual_rad = std::sqrt(chi2 / wsum * real(n) / real(n - 3));
    }
    const real x_m = q(0) - (cth * ox - sth * oy);
    const real y_m = q(1) - (sth * ox + cth * oy);
    const real theta_rad = wrap_angle(q(2));
    if (!is_finite(x_m) || !is_finite(y_m) || !is_finite(theta_rad) || !is_finite(residual_rad)) return BL_EDEGENERATE;

    bl_bearing_solution &sol = *out;
    std::memset(&sol, 0, sizeof sol);
    sol.x_m = x_m;
    sol.y_m = y_m;
    sol.theta_rad = theta_rad;
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) sol.cov[r * 3 + c] = cov(r, c);
    sol.drms_m = drms_m;
    sol.condition = condition;
    sol.residual_rms_rad = residual_rad;
    sol.iterations = iterations;
    return BL_OK;
}

// Closed form on beacons i, j, k: sensor fix q (theta unwrapped from the
// mean), its heading's unit vector; false when degenerate.
bool closed_form(const bl_bearing_problem *p, const Bearings &b, const uint32_t id[3], Vec3 &q, real &cth, real &sth)
{
    if (coincident(p, id[0], id[1], id[2])) return false;
    real xs, ys;
    if (!total(p, b, id[0], id[1], id[2], xs, ys)) return false;
    // A fix that does not reproduce its three bearings is no solution:
    // exactly on the degenerate circle D and k'31 both vanish and their
    // rounding-level quotient is an arbitrary point.
    real spread;
    if (!heading(p, b, id, xs, ys, cth, sth, spread) || !(spread <= kConsistency)) return false;
    q << xs, ys, std::atan2(sth, cth);
    return true;
}

}  // namespace

extern "C" int bl_solve_bearings_3(const bl_bearing_problem *prob, bl_bearing_solution *sol)
{
    if (prob == nullptr || sol == nullptr || !problem_valid(prob) || prob->count != 3 || displaced(prob))
        return BL_EINVAL;
    Bearings b;
    bearing_vectors(prob, b);
    Offsets off;
    sensor_offsets(prob, off);  // all zero
    static const uint32_t id[3] = {0, 1, 2};
    Vec3 q;
    real cth, sth;
    if (!closed_form(prob, b, id, q, cth, sth)) return BL_EDEGENERATE;
    Mat3 A;
    Vec3 g;
    real chi2;
    if (!normal_equations(prob, off, id, 3, q, false, A, g, chi2)) return BL_EDEGENERATE;
    return finish(prob, q, cth, sth, A, real(0), 3, 0, sol);
}

extern "C" int bl_solve_bearings(const bl_bearing_problem *prob, bl_bearing_solution *sol)
{
    if (prob == nullptr || sol == nullptr || !problem_valid(prob)) return BL_EINVAL;
    const uint32_t N = prob->count;
    Bearings b;
    bearing_vectors(prob, b);
    Offsets off;
    sensor_offsets(prob, off);
    uint32_t all[BL_MAX_BEACONS];
    for (uint32_t j = 0; j < N; ++j) all[j] = j;

    // Start: the closed form of every triple, keeping the one whose own
    // normal matrix is best conditioned (condition_of in the sensor's
    // unknowns).
    Vec3 q = Vec3::Zero();
    real best = -1;
    Mat3 A, inv;
    Vec3 g;
    real chi2;
    for (uint32_t i = 0; i < N; ++i)
        for (uint32_t j = i + 1; j < N; ++j)
            for (uint32_t k = j + 1; k < N; ++k) {
                const uint32_t id[3] = {i, j, k};
                Vec3 qt;
                real c, s;
                if (!closed_form(prob, b, id, qt, c, s)) continue;
                if (!normal_equations(prob, off, id, 3, qt, false, A, g, chi2) || !scaled_inverse(A, inv)) continue;
                const real cond = condition_of(A, inv);
                if (cond > best) {
                    best = cond;
                    q = qt;
                }
            }
    if (!(best > real(0))) return BL_EDEGENERATE;

    // Gauss-Newton on all N bearings (weighted least squares of the wrapped
    // residuals): q <- q + (JᵀWJ)⁻¹ JᵀW e.
    uint32_t it = 0;
    bool converged = false;
    while (it < kMaxIterations) {
        if (!normal_equations(prob, off, all, N, q, true, A, g, chi2) || !scaled_inverse(A, inv)) return BL_EDEGENERATE;
        const Vec3 step = inv * g;
        if (!step.allFinite()) return BL_EDEGENERATE;
        q += step;
        ++it;
        if (!q.allFinite()) return BL_EDEGENERATE;
        bool small = true;
        for (int k = 0; k < 3; ++k)
            small = small && std::fabs(step(k)) < std::fmax(kStepTol, kStepRel * std::sqrt(inv(k, k)));
        if (small) {
            converged = true;
            break;
        }
    }
    if (!converged) return BL_ENOCONVERGE;
    if (!normal_equations(prob, off, all, N, q, true, A, g, chi2)) return BL_EDEGENERATE;
    return finish(prob, q, std::cos(q(2)), std::sin(q(2)), A, chi2, N, it, sol);
}
