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

}  // namespace bl
