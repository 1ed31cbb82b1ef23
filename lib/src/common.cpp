// beaconloc — error texts (common.h).
#include "internal.hpp"

extern "C" const char *bl_strerror(int err)
{
    switch (err) {
    case BL_OK:
        return "ok";
    case BL_EINVAL:
        return "invalid argument (NULL, NaN/inf or out of range)";
    case BL_ECONFIG:
        return "configuration inconsistent";
    case BL_ETIME:
        return "time went backwards or jumped beyond the limit";
    case BL_EBEACON:
        return "unknown beacon id";
    case BL_ENOTINIT:
        return "not initialised or no estimate yet";
    case BL_EDEGENERATE:
        return "degenerate geometry";
    case BL_ENOCONVERGE:
        return "iteration did not converge";
    case BL_EFULL:
        return "buffer full";
    default:
        return "unknown error";
    }
}
