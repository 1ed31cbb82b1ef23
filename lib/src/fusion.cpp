// beaconloc — the parts of the shared scalar measurement update
// (fuse_scalar, fusion.hpp) that do not depend on the model.
#include "fusion.hpp"

#include <cstring>

namespace bl {

void symmetrise(MX &P)
{
    for (int r = 0; r < NX; ++r)
        for (int c = r + 1; c < NX; ++c) P(r, c) = P(c, r) = real(0.5) * (P(r, c) + P(c, r));
}

bool outside_gate(const ScalarMeasurement &m, real h, real S, bl_fusion_result *res)
{
    std::memset(res, 0, sizeof *res);
    res->innovation = m.z - h;
    res->innovation_var = S;
    if (!(m.gate_sigma > real(0))) return false;  // ungated: test ratio 0
    // Chi-square gate (1 dof, Kleeman §3.9): an echoed or outlying measurement.
    res->test_ratio = std::fabs(res->innovation) / (m.gate_sigma * std::sqrt(S));
    return !(res->test_ratio <= real(1));
}

// Joseph form and storage (fusion.hpp: the expansion and why it holds for
// any gain).
template <int N> bool joseph_upper(const MN<N> &P, const VN<N> &K, const VN<N> &u, real s, real *up, VN<N> *diag)
{
    real nan_if_not_finite = 0;  // v·0 is 0 for a finite v, NaN for ±inf and NaN
    real *out = up;
    for (int r = 0; r < N; ++r) {
        const real kr = K(r), ur = u(r), sk = s * kr;
        real v = P(r, r) - kr * ur;
        v -= ur * kr;
        v += sk * kr;
        (*diag)(r) = v;
        *out++ = v;
        nan_if_not_finite += v * real(0);
        for (int c = r + 1; c < N; ++c) {
            real w = P(r, c) - kr * u(c);
            w -= ur * K(c);
            w += sk * K(c);
            *out++ = w;
            nan_if_not_finite += w * real(0);
        }
    }
    return nan_if_not_finite == real(0);
}
template <int N> void store_symmetric(const real *up, MN<N> &P)
{
    const real *in = up;
    for (int r = 0; r < N; ++r) {
        P(r, r) = *in++;
        for (int c = r + 1; c < N; ++c) P(r, c) = P(c, r) = *in++;
    }
}
template <int N> real project(const MN<N> &P, const RN<N> &H, int unit, real R, VN<N> *PHt)
{
    *PHt = unit >= 0 ? VN<N>(P.col(unit)) : VN<N>(P.lazyProduct(H.transpose()));
    return (unit >= 0 ? P(unit, unit) : H.dot(*PHt)) + R;
}

template bool joseph_upper<NX>(const MX &, const VX &, const VX &, real, real *, VX *);
template void store_symmetric<NX>(const real *, MX &);
template real project<NX>(const MX &, const RX &, int, real, VX *);
#if BL_WITH_TEAM
template bool joseph_upper<kTeamNA>(const MN<kTeamNA> &, const VN<kTeamNA> &, const VN<kTeamNA> &, real, real *,
                                    VN<kTeamNA> *);
template void store_symmetric<kTeamNA>(const real *, MN<kTeamNA> &);
template real project<kTeamNA>(const MN<kTeamNA> &, const RN<kTeamNA> &, int, real, VN<kTeamNA> *);
#endif

}  // namespace bl
