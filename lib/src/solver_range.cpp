// beaconloc — range-only snapshot solver: 2D trilateration of a receiver at
// a known height from its 3D distances to N >= 3 fixed beacons (aid_range.h,
// bl_solve_ranges_2d), with the mirror ambiguity of (nearly) collinear
// beacons reported instead of guessed.
#include <cstring>

#include "internal.hpp"

extern "C" {
#include "beaconloc/aid_range.h"
}

using namespace bl;

namespace {

constexpr uint32_t kDefaultIterations = 20;
#if defined(BL_USE_FLOAT) && BL_USE_FLOAT
constexpr real kDefaultTolerance_m = real(1e-6);
#else
constexpr real kDefaultTolerance_m = real(1e-9);
#endif
// A mirror fix within this weighted residual sum of squares of the best
// one fits as well (a 3σ difference: chi-square with 1 dof at 9).
constexpr real kMirrorChi2 = real(9);

struct Fit {
    Vec2 p;
    real chi2;  // weighted residual sum of squares (1)
    real ssr;   // unweighted residual sum of squares (m²)
    Mat<2, 2> cov;
    uint32_t iterations;
};

bool valid(const bl_range_problem *pr)
{
    if (pr->count < 3 || pr->count > BL_MAX_BEACONS) return false;
    if (!is_finite(pr->receiver_z_m) || !is_finite(pr->tolerance_m) || pr->tolerance_m < real(0)) return false;
    if (pr->max_iterations > 100) return false;
    for (uint32_t j = 0; j < pr->count; ++j) {
        const bl_beacon &b = pr->beacons[j];
        if (!is_finite(b.x_m) || !is_finite(b.y_m) || !is_finite(b.z_m)) return false;
        if (!is_finite(pr->range_m[j]) || pr->range_m[j] < real(0)) return false;
        if (!is_finite(pr->sigma_m[j]) || !(pr->sigma_m[j] > real(0))) return false;
    }
    return true;
}

// Squared horizontal range ρ_j² = r_j² - (z_j - z)² (m²); may be negative
// with noise (the receiver under a beacon).
real rho2(const bl_range_problem *pr, uint32_t j)
{
    const real dz = pr->beacons[j].z_m - pr->receiver_z_m;
    return pr->range_m[j] * pr->range_m[j] - dz * dz;
}

// Weighted Gauss-Newton from p: e_j = r_j - |p3 - b_j| (m),
// ∂|p3 - b_j|/∂(x, y) = (p - b_j)_xy / d_j. False when the normal matrix is
// singular or a non-finite value appears; *converged false when no step
// fell below tol.
bool gauss_newton(const bl_range_problem *pr, Vec2 p, uint32_t max_it, real tol, Fit *out, bool *converged)
{
    *converged = false;
    Mat<2, 2> N;
    uint32_t it = 0;
    for (;;) {
        N.setZero();
        Vec2 g = Vec2::Zero();
        real chi2 = 0, ssr = 0;
        for (uint32_t j = 0; j < pr->count; ++j) {
            const bl_beacon &b = pr->beacons[j];
            const real dx = p(0) - b.x_m, dy = p(1) - b.y_m, dz = pr->receiver_z_m - b.z_m;
            const real d = std::sqrt(dx * dx + dy * dy + dz * dz);
            if (!(d > real(1e-9))) return false;
            const real e = pr->range_m[j] - d;
            const real w = real(1) / (pr->sigma_m[j] * pr->sigma_m[j]);
            const Vec2 J(dx / d, dy / d);
            N.noalias() += w * J * J.transpose();
            g.noalias() += w * J * e;
            chi2 += w * e * e;
            ssr += e * e;
        }
        const real det = N(0, 0) * N(1, 1) - N(0, 1) * N(1, 0);
        const real tr = N(0, 0) + N(1, 1);
        // Singular: the receiver on the beacons' line with no perpendicular
        // information, or every beacon above it.
        if (!(det > real(1e-12) * tr * tr) || !is_finite(det)) return false;
        Mat<2, 2> C;
        C << N(1, 1) / det, -N(0, 1) / det, -N(1, 0) / det, N(0, 0) / det;
        out->p = p;
        out->chi2 = chi2;
        out->ssr = ssr;
        out->cov = C;
        out->iterations = it;
        if (*converged || it >= max_it) return p.allFinite() && C.allFinite();
        const Vec2 step = C * g;
        if (!step.allFinite()) return false;
        p += step;
        ++it;
        // One more pass computes chi2 and the covariance at the final p.
        if (step.norm() < tol) *converged = true;
    }
}

// The beacons' principal line in x-y: centroid c, unit direction e, unit
// normal n, and the largest |distance| of a beacon from it (m) and the
// largest spread along it (m).
void principal_line(const bl_range_problem *pr, Vec2 *c, Vec2 *e, Vec2 *n, real *off_m, real *along_m)
{
    Vec2 m = Vec2::Zero();
    for (uint32_t j = 0; j < pr->count; ++j) m += Vec2(pr->beacons[j].x_m, pr->beacons[j].y_m);
    m /= real(pr->count);
    real sxx = 0, sxy = 0, syy = 0;
    for (uint32_t j = 0; j < pr->count; ++j) {
        const real dx = pr->beacons[j].x_m - m(0), dy = pr->beacons[j].y_m - m(1);
        sxx += dx * dx;
        sxy += dx * dy;
        syy += dy * dy;
    }
    // Major axis of the 2x2 scatter matrix: angle ½·atan2(2 sxy, sxx - syy).
    const real a = real(0.5) * std::atan2(real(2) * sxy, sxx - syy);
    *c = m;
    *e = Vec2(std::cos(a), std::sin(a));
    *n = Vec2(-std::sin(a), std::cos(a));
    real off = 0, along = 0;
    for (uint32_t j = 0; j < pr->count; ++j) {
        const Vec2 d(pr->beacons[j].x_m - m(0), pr->beacons[j].y_m - m(1));
        off = std::fmax(off, std::fabs(d.dot(*n)));
        along = std::fmax(along, std::fabs(d.dot(*e)));
    }
    *off_m = off;
    *along_m = along;
}

// The linearised closed form (aid_range.h): rows 2 (b_j - b_0)·p = ρ_0² - ρ_j²
// + |b_j|² - |b_0|², in coordinates relative to the centroid (better
// conditioned), solved by least squares. False when the rows do not span
// the plane (collinear beacons).
bool linear_start(const bl_range_problem *pr, const Vec2 &c, Vec2 *p)
{
    Mat<2, 2> A = Mat<2, 2>::Zero();
    Vec2 rhs = Vec2::Zero();
    const Vec2 b0(pr->beacons[0].x_m - c(0), pr->beacons[0].y_m - c(1));
    const real r0 = rho2(pr, 0);
    for (uint32_t j = 1; j < pr->count; ++j) {
        const Vec2 bj(pr->beacons[j].x_m - c(0), pr->beacons[j].y_m - c(1));
        const Vec2 a = real(2) * (bj - b0);
        const real y = r0 - rho2(pr, j) + bj.squaredNorm() - b0.squaredNorm();
        A.noalias() += a * a.transpose();
        rhs += a * y;
    }
    const real det = A(0, 0) * A(1, 1) - A(0, 1) * A(1, 0);
    const real tr = A(0, 0) + A(1, 1);
    if (!(det > real(1e-10) * tr * tr)) return false;
    *p = c + Vec2(A(1, 1) * rhs(0) - A(0, 1) * rhs(1), -A(1, 0) * rhs(0) + A(0, 0) * rhs(1)) / det;
    return p->allFinite();
}

// Collinear beacons: the same rows along the line (coordinate u), then the
// distance from the line w = sqrt(mean(ρ_j² - (u - u_j)²)) (clamped at 0):
// the candidate on the +n side.
Vec2 line_start(const bl_range_problem *pr, const Vec2 &c, const Vec2 &e, const Vec2 &n)
{
    real num = 0, den = 0;
    const real u0 = Vec2(pr->beacons[0].x_m - c(0), pr->beacons[0].y_m - c(1)).dot(e);
    const real r0 = rho2(pr, 0);
    for (uint32_t j = 1; j < pr->count; ++j) {
        const real uj = Vec2(pr->beacons[j].x_m - c(0), pr->beacons[j].y_m - c(1)).dot(e);
        const real a = real(2) * (uj - u0);
        const real y = r0 - rho2(pr, j) + uj * uj - u0 * u0;
        num += a * y;
        den += a * a;
    }
    const real u = den > real(0) ? num / den : real(0);
    real w2 = 0;
    for (uint32_t j = 0; j < pr->count; ++j) {
        const real uj = Vec2(pr->beacons[j].x_m - c(0), pr->beacons[j].y_m - c(1)).dot(e);
        w2 += rho2(pr, j) - (u - uj) * (u - uj);
    }
    w2 /= real(pr->count);
    const real w = w2 > real(0) ? std::sqrt(w2) : real(0);
    // Off the line by a hair so the normal matrix is not singular at the start.
    return c + u * e + (w > real(1e-6) ? w : real(1e-6)) * n;
}

}  // namespace

extern "C" int bl_solve_ranges_2d(const bl_range_problem *prob, bl_range_solution *sol)
{
    if (prob == nullptr || sol == nullptr || !valid(prob)) return BL_EINVAL;
    const uint32_t max_it = prob->max_iterations > 0 ? prob->max_iterations : kDefaultIterations;
    const real tol = prob->tolerance_m > real(0) ? prob->tolerance_m : kDefaultTolerance_m;
    Vec2 c, e, n;
    real off_m, along_m;
    principal_line(prob, &c, &e, &n, &off_m, &along_m);
    if (!(along_m > real(1e-6))) return BL_EDEGENERATE;  // all beacons at one point in x-y
    Vec2 p0;
    if (!linear_start(prob, c, &p0)) p0 = line_start(prob, c, e, n);
    Fit best;
    bool conv = false;
    if (!gauss_newton(prob, p0, max_it, tol, &best, &conv)) return BL_EDEGENERATE;
    if (!conv) return BL_ENOCONVERGE;
    // The mirror image of the fix across the beacons' line, refined.
    bool ambiguous = false;
    Fit other = best;
    const real drms = std::sqrt(best.cov(0, 0) + best.cov(1, 1));
    const real sep = std::fmax(real(3) * drms, real(1e-3));
    const real dist_n = (best.p - c).dot(n);
    if (std::fabs(real(2) * dist_n) > sep) {
        Fit mir;
        bool mconv = false;
        const Vec2 pm = best.p - real(2) * dist_n * n;
        if (gauss_newton(prob, pm, max_it, tol, &mir, &mconv) && mconv && (mir.p - best.p).norm() > sep &&
            mir.chi2 <= best.chi2 + kMirrorChi2) {
            ambiguous = true;
            if (mir.chi2 < best.chi2) {
                other = best;
                best = mir;
            } else {
                other = mir;
            }
        }
    }
    real s2 = 0;
    for (uint32_t j = 0; j < prob->count; ++j) s2 += prob->sigma_m[j] * prob->sigma_m[j];
    const real sigma_rms = std::sqrt(s2 / real(prob->count));
    bl_range_solution out;
    std::memset(&out, 0, sizeof out);
    out.x_m = best.p(0);
    out.y_m = best.p(1);
    for (int r = 0; r < 2; ++r)
        for (int k = 0; k < 2; ++k) out.cov[r * 2 + k] = best.cov(r, k);
    out.drms_m = std::sqrt(best.cov(0, 0) + best.cov(1, 1));
    out.hdop = out.drms_m / sigma_rms;
    out.residual_rms_m = std::sqrt(best.ssr / real(prob->count));
    out.chi2 = best.chi2;
    out.iterations = best.iterations;
    out.ambiguous = ambiguous;
    out.mirror_x_m = other.p(0);
    out.mirror_y_m = other.p(1);
    const real v[] = {out.x_m,    out.y_m,  out.cov[0],     out.cov[1],    out.cov[3],
                      out.drms_m, out.hdop, out.mirror_x_m, out.mirror_y_m};
    for (real x : v)
        if (!is_finite(x)) return BL_EDEGENERATE;
    *sol = out;
    return BL_OK;
}
