// beaconloc — team initialisation without fixed beacons (aid_team.h,
// bl_solve_team): the CMU Millibots' start-up (Navarro-Serment et al.
// §3.2) from the ranges between pairs of robots, by classical
// multidimensional scaling (Torgerson 1952) refined by weighted least
// squares, with its gauge-fixed covariance; the mirror reflection
// (bl_team_mirror) and its resolution by an L-shaped manoeuvre
// (bl_team_resolve_mirror).
#include "internal.hpp"

// The whole source compiles out without the team (common.h BL_WITH_TEAM).
#if BL_WITH_TEAM

#include <algorithm>
#include <cstring>
#include <limits>

#include "linalg.hpp"

extern "C" {
#include "beaconloc/aid_team.h"
}

using namespace bl;

namespace {

constexpr int kMaxN = BL_MAX_TEAM;
constexpr int kNP = 2 * kMaxN;  // coordinates (x0, y0, x1, y1, ...)
using VP = Mat<kNP, 1>;
using MP = Mat<kNP, kNP>;
using MT = Mat<kMaxN, kMaxN>;

constexpr uint32_t kDefaultIterations = 50;
#if defined(BL_USE_FLOAT) && BL_USE_FLOAT
constexpr real kDefaultTolerance_m = real(1e-6);
constexpr real kMinRcond = real(1e-6);
#else
constexpr real kDefaultTolerance_m = real(1e-9);
constexpr real kMinRcond = real(1e-12);
#endif

struct Pair {
    int i, j;
    real r_m;  // measured range (m)
    real w;    // 1/σ² (1/m²)
};

struct Pairs {
    Pair p[kMaxN * (kMaxN - 1) / 2];
    int n;
};

bool measured(const bl_team_problem *pr, uint32_t i, uint32_t j) { return is_finite(pr->range_m[i][j]); }

// Input checks of aid_team.h (BL_EINVAL).
bool valid(const bl_team_problem *pr)
{
    const uint32_t n = pr->count;
    if (n < 3 || n > uint32_t(kMaxN)) return false;
    if (pr->origin >= n || pr->axis >= n || pr->origin == pr->axis) return false;
    if (pr->max_iterations > 100 || !is_finite(pr->tolerance_m) || pr->tolerance_m < real(0)) return false;
    for (uint32_t i = 0; i < n; ++i)
        for (uint32_t j = 0; j < n; ++j) {
            if (i == j) continue;
            const real r = pr->range_m[i][j], rt = pr->range_m[j][i];
            if (std::isnan(r) && std::isnan(rt)) continue;  // not measured
            if (!is_finite(r) || !(r >= real(0)) || !(r == rt)) return false;
            const real s = pr->sigma_m[i][j];
            if (!is_finite(s) || !(s > real(0))) return false;
        }
    return true;
}

// Greedy placement (aid_team.h): origin and axis first, then any robot with
// >= 2 measured ranges to placed ones. Returns BL_TEAM_NONE when every
// robot is placed, else the robot at fault.
uint32_t unplaceable(const bl_team_problem *pr)
{
    const uint32_t n = pr->count, o = pr->origin, a = pr->axis;
    if (!measured(pr, o, a)) return a;
    const real r_oa = pr->range_m[o][a];
    if (!(r_oa >= real(3) * pr->sigma_m[o][a]) || !(r_oa >= real(1e-3))) return a;
    uint32_t placed = (1u << o) | (1u << a);
    for (;;) {
        bool progress = false;
        for (uint32_t i = 0; i < n && !progress; ++i) {
            if ((placed >> i) & 1u) continue;
            uint32_t links = 0;
            for (uint32_t j = 0; j < n; ++j)
                if (((placed >> j) & 1u) && measured(pr, i, j)) ++links;
            if (links >= 2) {
                placed |= 1u << i;
                progress = true;
            }
        }
        if (progress) continue;
        for (uint32_t i = 0; i < n; ++i)
            if (!((placed >> i) & 1u)) return i;
        return BL_TEAM_NONE;
    }
}

// Classical MDS start (Torgerson 1952; Borg & Groenen 2005 §12.1) in the
// gauge of aid_team.h. False when B has fewer than two positive eigenvalues
// (the team on one line: no 2D configuration).
bool mds_start(const bl_team_problem *pr, VP *p)
{
    const int n = int(pr->count);
    // Squared distances; a pair not measured gets the shortest path through
    // measured ones (Floyd–Warshall; MDS-MAP, Shang et al. 2003). The
    // placement check has made the graph connected.
    MT D = MT::Zero();
    const real inf = real(1e30);
    for (int i = 0; i < n; ++i)
        for (int j = 0; j < n; ++j)
            D(i, j) = i == j ? real(0) : (measured(pr, uint32_t(i), uint32_t(j)) ? pr->range_m[i][j] : inf);
    for (int k = 0; k < n; ++k)
        for (int i = 0; i < n; ++i)
            for (int j = 0; j < n; ++j)
                if (D(i, k) + D(k, j) < D(i, j)) D(i, j) = D(i, k) + D(k, j);
    // Double centring (Borg & Groenen eq. 12.1): B = -½ J D² J,
    // J = I - 11ᵀ/n, i.e. b_ij = -½ (d²_ij - d²_i. - d²_.j + d²_..).
    MT D2 = MT::Zero();
    for (int i = 0; i < n; ++i)
        for (int j = 0; j < n; ++j) D2(i, j) = D(i, j) * D(i, j);
    real row[kMaxN] = {};
    real all = 0;
    for (int i = 0; i < n; ++i) {
        for (int j = 0; j < n; ++j) row[i] += D2(i, j);
        all += row[i];
        row[i] /= real(n);
    }
    all /= real(n * n);
    MT B = MT::Zero();  // rows/columns beyond n stay 0: eigenvalues 0 there
    for (int i = 0; i < n; ++i)
        for (int j = 0; j < n; ++j) B(i, j) = real(-0.5) * (D2(i, j) - row[i] - row[j] + all);
    // The two largest eigenpairs: X = V₂ Λ₂^½ (Borg & Groenen eq. 12.2).
    // (Cyclic Jacobi, linalg.hpp: Eigen's SelfAdjointEigenSolver references
    // malloc through its GEMV kernel.)
    MT V;
    if (!symmetric_eigen<kMaxN>(B, &V)) return false;
    int i1 = 0, i2 = -1;
    for (int k = 1; k < kMaxN; ++k)
        if (B(k, k) > B(i1, i1)) i1 = k;
    for (int k = 0; k < kMaxN; ++k)
        if (k != i1 && (i2 < 0 || B(k, k) > B(i2, i2))) i2 = k;
    const real l1 = B(i1, i1), l2 = B(i2, i2);
    // A second eigenvalue at rounding level: the team on one line.
    if (!(l1 > real(0)) || !(l2 > kMinRcond * real(1e3) * l1)) return false;
    const real s1 = std::sqrt(l1), s2 = std::sqrt(l2);
    // The gauge: origin to (0, 0), axis onto +x.
    const int o = int(pr->origin), a = int(pr->axis);
    const real ox = V(o, i1) * s1, oy = V(o, i2) * s2;
    const real ax = V(a, i1) * s1 - ox, ay = V(a, i2) * s2 - oy;
    const real phi = std::atan2(ay, ax), c = std::cos(phi), s = std::sin(phi);
    p->setZero();
    for (int i = 0; i < n; ++i) {
        const real x = V(i, i1) * s1 - ox, y = V(i, i2) * s2 - oy;
        (*p)(2 * i) = c * x + s * y;  // R(-φ)·(x, y)
        (*p)(2 * i + 1) = -s * x + c * y;
    }
    (*p)(2 * o) = (*p)(2 * o + 1) = (*p)(2 * a + 1) = real(0);
    return p->allFinite();
}

// The coordinates the gauge leaves free (aid_team.h): all of robots < n but
// origin's x, y and axis's y.
void free_mask(const bl_team_problem *pr, bool freec[kNP])
{
    for (int k = 0; k < kNP; ++k) freec[k] = k < int(2 * pr->count);
    freec[2 * pr->origin] = freec[2 * pr->origin + 1] = false;
    freec[2 * pr->axis + 1] = false;
}

// χ² = Σ (r_ij - |p_i - p_j|)² w_ij at p; with A and g non-NULL also the
// normal equations of the free coordinates, A = JᵀWJ, g = JᵀW e (held
// coordinates: identity rows, zero g). False when two robots coincide.
bool normal_equations(const Pairs &pairs, const bool freec[kNP], const VP &p, real *chi2, real *ssr, MP *A, VP *g)
{
    real c2 = 0, s2 = 0;
    if (A) {
        A->setZero();
        g->setZero();
    }
    for (int k = 0; k < pairs.n; ++k) {
        const Pair &q = pairs.p[k];
        const real dx = p(2 * q.i) - p(2 * q.j), dy = p(2 * q.i + 1) - p(2 * q.j + 1);
        const real d = std::sqrt(dx * dx + dy * dy);
        if (!(d > real(1e-9))) return false;
        const real e = q.r_m - d;
        c2 += q.w * e * e;
        s2 += e * e;
        if (!A) continue;
        // ∂d/∂p_i = (dx, dy)/d = -∂d/∂p_j
        const int idx[4] = {2 * q.i, 2 * q.i + 1, 2 * q.j, 2 * q.j + 1};
        const real jac[4] = {dx / d, dy / d, -dx / d, -dy / d};
        for (int r = 0; r < 4; ++r) {
            if (!freec[idx[r]]) continue;
            (*g)(idx[r]) += q.w * jac[r] * e;
            for (int c = 0; c < 4; ++c)
                if (freec[idx[c]]) (*A)(idx[r], idx[c]) += q.w * jac[r] * jac[c];
        }
    }
    if (A)
        for (int k = 0; k < kNP; ++k)
            if (!freec[k]) (*A)(k, k) = real(1);
    *chi2 = c2;
    *ssr = s2;
    return is_finite(c2);
}

}  // namespace

extern "C" int bl_solve_team(const bl_team_problem *prob, bl_team_solution *sol)
{
    if (prob == nullptr || sol == nullptr || !valid(prob)) {
        if (sol) sol->failed_robot = BL_TEAM_NONE;
        return BL_EINVAL;
    }
    const uint32_t bad = unplaceable(prob);
    if (bad != BL_TEAM_NONE) {
        sol->failed_robot = bad;
        return BL_EDEGENERATE;
    }
    sol->failed_robot = BL_TEAM_NONE;
    const uint32_t n = prob->count;
    const uint32_t max_it = prob->max_iterations > 0 ? prob->max_iterations : kDefaultIterations;
    const real tol = prob->tolerance_m > real(0) ? prob->tolerance_m : kDefaultTolerance_m;
    Pairs pairs;
    pairs.n = 0;
    for (uint32_t i = 0; i < n; ++i)
        for (uint32_t j = i + 1; j < n; ++j)
            if (measured(prob, i, j))
                pairs.p[pairs.n++] = {int(i), int(j), prob->range_m[i][j],
                                      real(1) / (prob->sigma_m[i][j] * prob->sigma_m[i][j])};
    VP p;
    if (!mds_start(prob, &p)) return BL_EDEGENERATE;
    bool freec[kNP];
    free_mask(prob, freec);

    // Levenberg–Marquardt (Levenberg 1944; Marquardt 1963): solve
    // (A + λ diag(A)) δ = g (Cholesky, linalg.hpp), accept when χ² falls
    // (λ /= 10), else λ *= 10.
    real chi2, ssr;
    MP A;
    VP g;
    if (!normal_equations(pairs, freec, p, &chi2, &ssr, &A, &g)) return BL_EDEGENERATE;
    real lambda = real(1e-3);
    uint32_t it = 0;
    bool converged = false;
    while (it < max_it) {
        MP Al = A;
        for (int k = 0; k < kNP; ++k) Al(k, k) += lambda * A(k, k);
        MP L;
        ++it;
        if (!cholesky<kNP>(Al, &L, nullptr)) {
            lambda *= real(10);
            if (lambda > real(1e12)) return BL_EDEGENERATE;  // no damping makes it positive definite
            continue;
        }
        const VP step = cholesky_solve<kNP>(L, g);
        if (!step.allFinite()) return BL_EDEGENERATE;
        const real move = step.cwiseAbs().maxCoeff();
        const VP pn = p + step;
        real chi2n, ssrn;
        if (normal_equations(pairs, freec, pn, &chi2n, &ssrn, nullptr, nullptr) && chi2n <= chi2) {
            p = pn;
            if (!normal_equations(pairs, freec, p, &chi2, &ssr, &A, &g)) return BL_EDEGENERATE;
            lambda = std::fmax(lambda * real(0.1), real(1e-12));
        } else {
            lambda *= real(10);
        }
        if (move < tol) {
            converged = true;
            break;
        }
        if (lambda > real(1e12)) break;
    }
    if (!converged) return BL_ENOCONVERGE;

    // Covariance: the inverse of the gauge-fixed Fisher information JᵀWJ
    // (first order; held coordinates: zero).
    MP L;
    real ratio;
    if (!cholesky<kNP>(A, &L, &ratio) || !(ratio > kMinRcond)) return BL_EDEGENERATE;
    MP C = MP::Zero();
    for (int k = 0; k < kNP; ++k) {
        if (!freec[k]) continue;
        VP e = VP::Zero();
        e(k) = real(1);
        const VP col = cholesky_solve<kNP>(L, e);
        for (int r = 0; r < kNP; ++r) C(r, k) = freec[r] ? col(r) : real(0);
    }
    // symmetric to rounding: made exactly so (a filter checks it)
    for (int r = 0; r < kNP; ++r)
        for (int c = r + 1; c < kNP; ++c) C(r, c) = C(c, r) = real(0.5) * (C(r, c) + C(c, r));
    if (!C.allFinite() || !p.allFinite()) return BL_EDEGENERATE;

    // The reflection convention (aid_team.h): the lowest-numbered robot off
    // the x axis by more than 3σ_y has y > 0.
    for (uint32_t i = 0; i < n; ++i) {
        const real y = p(2 * i + 1), vy = C(2 * i + 1, 2 * i + 1);
        if (i == prob->origin || i == prob->axis || !(y * y > real(9) * vy)) continue;
        if (y < real(0)) {
            for (uint32_t k = 0; k < n; ++k) p(2 * k + 1) = -p(2 * k + 1);
            for (int r = 0; r < kNP; ++r)
                for (int c = 0; c < kNP; ++c)
                    if ((r + c) % 2 == 1) C(r, c) = -C(r, c);
        }
        break;
    }

    bl_team_solution out;
    std::memset(&out, 0, sizeof out);
    out.count = n;
    for (uint32_t i = 0; i < n; ++i) {
        out.x_m[i] = p(2 * i);
        out.y_m[i] = p(2 * i + 1);
        out.cov[i][0] = C(2 * i, 2 * i);
        out.cov[i][1] = C(2 * i, 2 * i + 1);
        out.cov[i][2] = C(2 * i + 1, 2 * i);
        out.cov[i][3] = C(2 * i + 1, 2 * i + 1);
    }
    for (int r = 0; r < kNP; ++r)
        for (int c = 0; c < kNP; ++c) out.joint_cov[r * kNP + c] = C(r, c);
    out.ranges_used = uint32_t(pairs.n);
    const int dof = pairs.n - int(2 * n - 3);
    out.dof = dof > 0 ? uint32_t(dof) : 0u;
    out.residual_rms_m = std::sqrt(ssr / real(pairs.n));
    out.chi2 = chi2;
    out.chi2_limit = chi2_quantile(out.dof, kZ95);
    out.chi2_ok = out.dof == 0 || chi2 <= out.chi2_limit;
    out.iterations = it;
    out.mirror_unresolved = true;
    out.failed_robot = BL_TEAM_NONE;
    *sol = out;
    return BL_OK;
}

extern "C" int bl_team_mirror(const bl_team_solution *in, bl_team_solution *out)
{
    if (in == nullptr || out == nullptr || in->count < 3 || in->count > uint32_t(kMaxN)) return BL_EINVAL;
    bl_team_solution m = *in;
    // y -> -y: the Jacobian diag(1, -1, 1, -1, ...) negates every entry
    // that pairs an x with a y.
    for (int i = 0; i < kMaxN; ++i) {
        m.y_m[i] = -in->y_m[i];
        m.cov[i][1] = -in->cov[i][1];
        m.cov[i][2] = -in->cov[i][2];
    }
    for (int r = 0; r < kNP; ++r)
        for (int c = 0; c < kNP; ++c)
            if ((r + c) % 2 == 1) m.joint_cov[r * kNP + c] = -in->joint_cov[r * kNP + c];
    m.mirror_unresolved = false;
    *out = m;
    return BL_OK;
}

extern "C" int bl_team_resolve_mirror(const bl_team_l_manoeuvre *in, bl_team_mirror_decision *out)
{
    if (in == nullptr || out == nullptr) return BL_EINVAL;
    for (int k = 0; k < 3; ++k) {
        if (!is_finite(in->x_m[k]) || !is_finite(in->y_m[k])) return BL_EINVAL;
        for (int e = 0; e < 4; ++e)
            if (!is_finite(in->cov[k][e])) return BL_EINVAL;
        if (in->cov[k][0] < real(0) || in->cov[k][3] < real(0)) return BL_EINVAL;
    }
    if (!is_finite(in->turn_rad) || !is_finite(in->sigma_turn_rad) || in->sigma_turn_rad < real(0) ||
        !is_finite(in->min_confidence) || in->min_confidence < real(0))
        return BL_EINVAL;
    const real zmin = in->min_confidence > real(0) ? in->min_confidence : real(3);
    const real ax = in->x_m[1] - in->x_m[0], ay = in->y_m[1] - in->y_m[0];
    const real bx = in->x_m[2] - in->x_m[1], by = in->y_m[2] - in->y_m[1];
    if (!(std::hypot(ax, ay) >= real(1e-3)) || !(std::hypot(bx, by) >= real(1e-3))) return BL_EDEGENERATE;
    // c = a × b (aid_team.h), its gradients, σ_c² = Σ gₖᵀ Σₖ gₖ.
    const real c = ax * by - ay * bx;
    const real gk[3][2] = {{-by, bx}, {by + ay, -bx - ax}, {-ay, ax}};
    real var = 0;
    for (int k = 0; k < 3; ++k) {
        const real *S = in->cov[k];
        var += gk[k][0] * (S[0] * gk[k][0] + S[1] * gk[k][1]) + gk[k][1] * (S[2] * gk[k][0] + S[3] * gk[k][1]);
    }
    if (!(var >= real(0)) || !is_finite(var)) return BL_EINVAL;
    const real sc = std::sqrt(var);
    const real conf = sc > real(0) ? std::fabs(c) / sc : (c != real(0) ? real(1e30) : real(0));
    if (!(conf >= zmin)) return BL_EDEGENERATE;  // too straight (or too short) to tell
    const real turn = in->turn_rad;
    if (!(std::fabs(turn) >= real(0.1)) || !(std::fabs(turn) >= zmin * in->sigma_turn_rad)) return BL_EDEGENERATE;
    bl_team_mirror_decision d;
    d.mirrored = (c > real(0)) != (turn > real(0));
    d.cross_m2 = c;
    d.sigma_cross_m2 = sc;
    d.confidence = conf;
    *out = d;
    return BL_OK;
}

// One pair's mean range with multipath late arrivals dropped (aid_team.h):
// median, robust σ = max(1.4826·MAD, σ model) (Huber 1981 §5.1), the mean of
// the ranges within 3 robust σ of the median (Millibots §3.2).
int bl_robust_range_mean(bl_real *v, bl_real *scratch, uint32_t m, bl_real sigma_m, bl_real sigma_per_m,
                         bl_real *mean_m, uint32_t *kept)
{
    constexpr real kOutlierSigma = real(3);
    constexpr real kMadToSigma = real(1.4826);
    if (!v || !scratch || !mean_m || !kept || m == 0 || !is_finite(sigma_m) || !is_finite(sigma_per_m) || sigma_m < 0 ||
        sigma_per_m < 0)
        return BL_EINVAL;
    for (uint32_t k = 0; k < m; ++k)
        if (!is_finite(v[k])) return BL_EINVAL;
    auto median_sorted = [m](const real *x) { return (m % 2) ? x[m / 2] : real(0.5) * (x[m / 2 - 1] + x[m / 2]); };
    std::sort(v, v + m);
    const real med = median_sorted(v);
    for (uint32_t k = 0; k < m; ++k) scratch[k] = std::fabs(v[k] - med);
    std::sort(scratch, scratch + m);
    const real rs = std::max(kMadToSigma * median_sorted(scratch), sigma_m + sigma_per_m * med);
    real sum = 0;
    uint32_t n = 0;
    for (uint32_t k = 0; k < m; ++k)
        if (std::fabs(v[k] - med) <= kOutlierSigma * rs) {
            sum += v[k];
            ++n;
        }
    *mean_m = n > 0 ? sum / real(n) : std::numeric_limits<real>::quiet_NaN();
    *kept = n;
    return BL_OK;
}

#endif  // BL_WITH_TEAM
