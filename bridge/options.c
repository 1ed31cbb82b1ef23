/*
 * beaconloc-bridge — the command line and the configuration layers.
 * Contracts: options.h.
 */
#include "options.h"

#include <errno.h>
#include <getopt.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "log.h"
#include "mavlink_out.h"

static void usage(FILE *f)
{
    fprintf(f,
            "usage: beaconloc-bridge [--site FILE] [--can IFACE] [--mavlink ENDPOINT]\n"
            "                        [--rate HZ] [--sysid N] [--compid N] [--log-level LEVEL]\n"
            "                        [--replay LOG [--realtime | --speed X]] [--record LOG]\n"
            "                        [--estimates CSV] [--stats JSON] [--status-interval S]\n"
            "                        [--initial-pose X,Y,HEADING_DEG,SIGMA_M[,SIGMA_HEADING_DEG]]\n"
            "                        [--param-file FILE]\n"
            "                        [--help] [--version]\n"
            "  --site FILE        site file (beacons, receivers, robot, noise, [bridge])\n"
            "  --can IFACE        SocketCAN interface (default vcan0)\n"
            "  --mavlink EP       udpout:HOST:PORT | udpin:HOST:PORT | serial:DEV:BAUD\n"
            "                     (repeat for up to 4 endpoints; each gets every message)\n"
            "  --rate HZ          ODOMETRY rate (default 30)\n"
            "  --sysid N --compid N   MAVLink ids (default 1, 197)\n"
            "  --log-level L      error, warning, info, debug\n"
            "  --replay LOG       read a candump log instead of the bus (as fast as possible)\n"
            "  --realtime         pace the replay at the log's own speed\n"
            "  --speed X          pace the replay at X times the log's speed\n"
            "  --record LOG       write every frame read to a candump log\n"
            "  --estimates CSV    write every estimate (receiver-node clock)\n"
            "  --stats JSON       write counters and latency at exit\n"
            "  --status-interval S  status line period in seconds (0 = off)\n"
            "  --initial-pose X,Y,HEADING_DEG,SIGMA_M[,SIGMA_HEADING_DEG]\n"
            "                     start from this pose (site frame, m and deg; sigma of x\n"
            "                     and y; heading sigma default 5 deg) instead of waiting\n"
            "                     for the beacons' snapshot\n"
            "  --param-file FILE  the MAVLink parameters' override file ([bridge] param_file)\n"
            "See docs/bridge.md.\n");
}

static int parse_double_opt(const char *name, const char *s, double lo, double hi, double *out)
{
    char *end;
    errno = 0;
    double v = strtod(s, &end);
    if (end == s || *end || errno || !isfinite(v) || v <= lo || v > hi) {
        fprintf(stderr,
                "error: command line: --%s: '%s' is not a number in "
                "(%g, %g]\n",
                name, s, lo, hi);
        return -1;
    }
    *out = v;
    return 0;
}

static int parse_id_opt(const char *name, const char *s, int *out)
{
    char *end;
    errno = 0;
    long v = strtol(s, &end, 10);
    if (end == s || *end || errno || v < 1 || v > 255) {
        fprintf(stderr, "error: command line: --%s: '%s' is not an id 1..255\n", name, s);
        return -1;
    }
    *out = (int)v;
    return 0;
}

/* "X,Y,HEADING_DEG,SIGMA_M[,SIGMA_HEADING_DEG]" -> *p (radians inside). */
static int parse_pose_opt(const char *s, struct est_initial_pose *p)
{
    double v[5] = {0, 0, 0, 0, 5.0};
    int n = 0;
    const char *q = s;
    while (n < 5) {
        char *end;
        errno = 0;
        v[n] = strtod(q, &end);
        if (end == q || errno || !isfinite(v[n]))
            break;
        n++;
        q = end;
        if (*q != ',')
            break;
        q++;
    }
    if ((n != 4 && n != 5) || *q || fabs(v[0]) > 1e4 || fabs(v[1]) > 1e4 || !(v[3] > 0) ||
        v[3] > 1e3 || !(v[4] > 0) || v[4] > 360) {
        fprintf(stderr,
                "error: command line: --initial-pose: '%s' is not X,Y,HEADING_DEG,SIGMA_M"
                "[,SIGMA_HEADING_DEG] (|X|, |Y| <= 1e4 m, 0 < SIGMA_M <= 1e3, "
                "0 < SIGMA_HEADING_DEG <= 360)\n",
                s);
        return -1;
    }
    p->set = true;
    p->x_m = v[0];
    p->y_m = v[1];
    p->heading_rad = v[2] * M_PI / 180.0;
    p->sigma_m = v[3];
    p->sigma_heading_rad = v[4] * M_PI / 180.0;
    return 0;
}

int parse_args(int argc, char **argv, struct options *o, int *status)
{
    enum {
        O_SITE = 256,
        O_CAN,
        O_MAV,
        O_RATE,
        O_SYSID,
        O_COMPID,
        O_LOGLEVEL,
        O_REPLAY,
        O_REALTIME,
        O_SPEED,
        O_RECORD,
        O_ESTIMATES,
        O_STATS,
        O_STATUS,
        O_POSE,
        O_PARAMFILE,
        O_VERSION
    };
    static const struct option longopts[] = {{"site", required_argument, 0, O_SITE},
                                             {"can", required_argument, 0, O_CAN},
                                             {"mavlink", required_argument, 0, O_MAV},
                                             {"rate", required_argument, 0, O_RATE},
                                             {"sysid", required_argument, 0, O_SYSID},
                                             {"compid", required_argument, 0, O_COMPID},
                                             {"log-level", required_argument, 0, O_LOGLEVEL},
                                             {"replay", required_argument, 0, O_REPLAY},
                                             {"realtime", no_argument, 0, O_REALTIME},
                                             {"speed", required_argument, 0, O_SPEED},
                                             {"record", required_argument, 0, O_RECORD},
                                             {"estimates", required_argument, 0, O_ESTIMATES},
                                             {"stats", required_argument, 0, O_STATS},
                                             {"status-interval", required_argument, 0, O_STATUS},
                                             {"initial-pose", required_argument, 0, O_POSE},
                                             {"param-file", required_argument, 0, O_PARAMFILE},
                                             {"help", no_argument, 0, 'h'},
                                             {"version", no_argument, 0, O_VERSION},
                                             {0, 0, 0, 0}};
    memset(o, 0, sizeof *o);
    o->status_interval_s = -1;
    int c;
    opterr = 0;
    while ((c = getopt_long(argc, argv, "h", longopts, NULL)) != -1) {
        int rc = 0;
        switch (c) {
        case O_SITE:
            o->site = optarg;
            break;
        case O_CAN:
            o->can = optarg;
            break;
        case O_MAV:
            if (!o->mavlink)
                o->mavlink = optarg;
            else if (o->n_mavlink_more < MAV_LINKS_MAX - 1)
                o->mavlink_more[o->n_mavlink_more++] = optarg;
            else {
                fprintf(stderr, "error: command line: --mavlink: at most %d endpoints\n",
                        MAV_LINKS_MAX);
                *status = EX_USAGE_STATUS;
                return -1;
            }
            break;
        case O_RATE:
            rc = parse_double_opt("rate", optarg, 0, 1000, &o->rate_hz);
            break;
        case O_SYSID:
            rc = parse_id_opt("sysid", optarg, &o->sysid);
            break;
        case O_COMPID:
            rc = parse_id_opt("compid", optarg, &o->compid);
            break;
        case O_LOGLEVEL:
            o->log_level = optarg;
            break;
        case O_REPLAY:
            o->replay = optarg;
            break;
        case O_REALTIME:
            o->speed = 1.0;
            break;
        case O_SPEED:
            rc = parse_double_opt("speed", optarg, 0, 1e6, &o->speed);
            break;
        case O_RECORD:
            o->record = optarg;
            break;
        case O_ESTIMATES:
            o->estimates = optarg;
            break;
        case O_STATS:
            o->stats = optarg;
            break;
        case O_STATUS: {
            double v;
            if (!strcmp(optarg, "0"))
                o->status_interval_s = 0;
            else if (!(rc = parse_double_opt("status-interval", optarg, 0, 86400, &v)))
                o->status_interval_s = v;
            break;
        }
        case O_POSE:
            rc = parse_pose_opt(optarg, &o->initial_pose);
            break;
        case O_PARAMFILE:
            o->param_file = optarg;
            break;
        case 'h':
            usage(stdout);
            *status = EX_OK_STATUS;
            return -1;
        case O_VERSION:
            printf("beaconloc-bridge %s\n", BRIDGE_VERSION);
            *status = EX_OK_STATUS;
            return -1;
        default:
            fprintf(stderr, "error: command line: unknown or incomplete option '%s'\n",
                    argv[optind - 1]);
            usage(stderr);
            *status = EX_USAGE_STATUS;
            return -1;
        }
        if (rc) {
            *status = EX_CONFIG_STATUS;
            return -1;
        }
    }
    if (optind < argc) {
        fprintf(stderr, "error: command line: unexpected argument '%s'\n", argv[optind]);
        usage(stderr);
        *status = EX_USAGE_STATUS;
        return -1;
    }
    if (o->speed > 0 && !o->replay) {
        fprintf(stderr, "error: command line: --realtime/--speed need --replay\n");
        *status = EX_USAGE_STATUS;
        return -1;
    }
    return 0;
}

int build_config(const struct options *o, struct bridge_config *cfg)
{
    char err[CONFIG_ERR_LEN];
    config_defaults(cfg);
    if (o->site && config_load_file(cfg, o->site, err, sizeof err) != 0) {
        fprintf(stderr, "error: %s\n", err);
        return -1;
    }
    if (o->param_file) {
        if (!o->param_file[0] || strlen(o->param_file) >= sizeof cfg->param_file) {
            fprintf(stderr, "error: command line: --param-file: '%s' is not a file name\n",
                    o->param_file);
            return -1;
        }
        snprintf(cfg->param_file, sizeof cfg->param_file, "%s", o->param_file);
    }
    /* the parameters set over MAVLink ([bridge] param_file, bridge/params.h):
     * a site-file fragment over the site file; none yet is no error */
    if (cfg->param_file[0] && access(cfg->param_file, F_OK) == 0) {
        char site_path[sizeof cfg->path];
        memcpy(site_path, cfg->path, sizeof site_path);
        char param_file[sizeof cfg->param_file];
        memcpy(param_file, cfg->param_file, sizeof param_file);
        if (config_load_file(cfg, param_file, err, sizeof err) != 0) {
            fprintf(stderr, "error: %s\n", err);
            return -1;
        }
        memcpy(cfg->path, site_path, sizeof site_path); /* errors name the site file */
    }
    if (o->can) {
        if (!o->can[0] || strlen(o->can) >= 16) {
            fprintf(stderr, "error: command line: --can: '%s' is not an interface name\n", o->can);
            return -1;
        }
        snprintf(cfg->can_interface, sizeof cfg->can_interface, "%s", o->can);
    }
    if (o->mavlink) {
        if (strlen(o->mavlink) >= sizeof cfg->mavlink) {
            fprintf(stderr, "error: command line: --mavlink: too long\n");
            return -1;
        }
        snprintf(cfg->mavlink, sizeof cfg->mavlink, "%s", o->mavlink);
    }
    if (o->rate_hz > 0)
        cfg->odometry_rate_hz = o->rate_hz;
    if (o->sysid)
        cfg->system_id = o->sysid;
    if (o->compid)
        cfg->component_id = o->compid;
    if (o->log_level)
        snprintf(cfg->log_level, sizeof cfg->log_level, "%s", o->log_level);
    if (o->status_interval_s >= 0)
        cfg->status_interval_s = o->status_interval_s;
    enum log_level lv;
    if (log_level_parse(cfg->log_level, &lv) != 0) {
        fprintf(stderr, "error: command line: --log-level: unknown level '%s'\n", cfg->log_level);
        return -1;
    }
    struct mav_endpoint ep;
    if (mav_endpoint_parse(cfg->mavlink, &ep) != 0) {
        if (o->mavlink)
            fprintf(stderr,
                    "error: command line: --mavlink: '%s' is not "
                    "udpout:HOST:PORT, udpin:HOST:PORT or serial:DEVICE:BAUD\n",
                    cfg->mavlink);
        else
            config_format_error(cfg, "bridge", "mavlink", "not a valid endpoint", err, sizeof err),
                fprintf(stderr, "error: %s\n", err);
        return -1;
    }
    for (int i = 0; i < o->n_mavlink_more; i++)
        if (strlen(o->mavlink_more[i]) >= MAV_LINK_SPEC_MAX ||
            mav_endpoint_parse(o->mavlink_more[i], &ep) != 0) {
            fprintf(stderr,
                    "error: command line: --mavlink: '%s' is not "
                    "udpout:HOST:PORT, udpin:HOST:PORT or serial:DEVICE:BAUD\n",
                    o->mavlink_more[i]);
            return -1;
        }
    if (config_check(cfg, err, sizeof err) != 0) {
        if (!o->site)
            fprintf(stderr, "error: no beacons configured: give the site file with --site FILE\n");
        else
            fprintf(stderr, "error: %s\n", err);
        return -1;
    }
    return 0;
}
