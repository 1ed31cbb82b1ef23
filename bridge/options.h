/*
 * beaconloc-bridge — the command line (getopt_long) and the configuration
 * layers: defaults < site file < the parameters' override file ([bridge]
 * param_file or --param-file, bridge/params.h) < command line
 * (docs/bridge.md, OPTIONS).
 */
#ifndef BRIDGE_OPTIONS_H
#define BRIDGE_OPTIONS_H

#include "config.h"
#include "estimator.h"
#include "mav_links.h"

#define EX_OK_STATUS 0
#define EX_USAGE_STATUS 64
#define EX_NOINPUT_STATUS 66
#define EX_SOFTWARE_STATUS 70
#define EX_CANTCREAT_STATUS 73

#define BRIDGE_VERSION "0.1.0"

/* What the command line gave; the strings point into argv. */
struct options {
    const char *site;
    const char *can;
    const char *mavlink; /* the first --mavlink (overrides [bridge] mavlink) */
    const char *mavlink_more[MAV_LINKS_MAX - 1]; /* further --mavlink endpoints */
    int n_mavlink_more;
    const char *replay;
    const char *record;
    const char *estimates;
    const char *stats;
    const char *param_file; /* --param-file (overrides [bridge] param_file) */
    const char *log_level;
    double rate_hz;                       /* 0 = not given */
    int sysid, compid;                    /* 0 = not given */
    double speed;                         /* paced replay speed factor, 0 = fast */
    double status_interval_s;             /* <0 = not given */
    struct est_initial_pose initial_pose; /* --initial-pose (set false: not given) */
};

/* Parse argv into *o. Returns 0, or -1 when the program is to exit now with
 * *status (--help, --version: 0; a usage error: EX_USAGE_STATUS; a bad
 * value: EX_CONFIG_STATUS), the message printed. */
int parse_args(int argc, char **argv, struct options *o, int *status);

/* Layers: defaults < site file < override file < command line, every
 * endpoint checked. Returns 0 or -1 (message printed). */
int build_config(const struct options *o, struct bridge_config *cfg);

#endif /* BRIDGE_OPTIONS_H */
